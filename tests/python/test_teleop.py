"""The Python module `teleop` (docs/python.md), run by ctest with Debian's /usr/bin/python3.

Each result is checked against an independent path: `teleopctl` run as a process on the same
file (the CLI's --json and --out), a closed form from the physics, or the papers.

Environment (set by tests/python/CMakeLists.txt): PYTHONPATH holds the built module,
TELEOPCTL the teleopctl binary, TELEOP_SOURCE_DIR the source tree, TELEOP_DESCRIPTOR_SET the
built teleop.desc.
"""

import csv
import json
import math
import os
import pathlib
import subprocess
import tempfile
import unittest

import numpy as np

import teleop

TELEOPCTL = os.environ["TELEOPCTL"]
SOURCE = pathlib.Path(os.environ["TELEOP_SOURCE_DIR"])
PADDLES = SOURCE / "examples" / "paddles.textproto"
STABLE_SCENE = SOURCE / "examples" / "scenes" / "paddles_slave_fixture_stable.textproto"


def run_cli(*args, expect=None):
    """teleopctl as a process: (exit code, stdout, stderr)."""
    p = subprocess.run([TELEOPCTL, *map(str, args)], capture_output=True, text=True, check=False)
    if expect is not None and p.returncode not in expect:
        raise AssertionError(f"teleopctl {args}: exit {p.returncode}\n{p.stderr}")
    return p.returncode, p.stdout, p.stderr


def without_effort(doc):
    """The document without "evaluations": how many spectra a stiffness search computed depends
    on how its threads (common/stability) were scheduled, and differs between two runs of the
    CLI itself; the limits do not."""
    if isinstance(doc, dict):
        return {k: without_effort(v) for k, v in doc.items() if k != "evaluations"}
    if isinstance(doc, list):
        return [without_effort(v) for v in doc]
    return doc


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], np.array([[float(v) for v in r] for r in rows[1:]])
    return {name: body[:, i] for i, name in enumerate(header)}


class Version(unittest.TestCase):
    def test_version_is_teleopctls(self):
        _, out, _ = run_cli("--version", expect=[0])
        self.assertEqual(out.strip(), f"teleopctl {teleop.__version__}")


class Analyze(unittest.TestCase):
    def test_agrees_with_the_cli_json(self):
        # The same file and override through the CLI process and through the module.
        _, out, _ = run_cli("analyze", PADDLES, "--set", "gains.kps=500", "--json", expect=[0, 3, 4])
        cli = json.loads(out)
        py = teleop.analyze(PADDLES.read_text(), **{"gains.kps": 500})
        self.assertEqual(py, cli)
        # The overrides as a dict, and the file as a path, give the same document.
        self.assertEqual(teleop.analyze(PADDLES, {"gains.kps": 500}), cli)
        self.assertEqual(cli["verdict"], "stable")

    def test_an_override_changes_the_result(self):
        # A slave fixture far above the paper's range (Fig. 6: the eigenvalues leave the unit
        # circle between 500 and 5500 N/m) is unstable; the shipped 1500 N/m is stable.
        self.assertEqual(teleop.analyze(PADDLES)["verdict"], "stable")
        stiff = teleop.analyze(PADDLES, **{"slave.fixture.stiffness_N_per_m": 50000})
        self.assertEqual(stiff["verdict"], "unstable")
        self.assertGreater(stiff["spectral_radius"], 1.0)

    def assert_same_error_as_cli(self, path, value):
        code, _, err = run_cli("analyze", PADDLES, "--set", f"{path}={value}")
        self.assertEqual(code, 1)
        lines = err.strip().split("\n")
        self.assertEqual(lines[0], "teleopctl analyze: invalid configuration:")
        with self.assertRaises(ValueError) as caught:
            teleop.analyze(PADDLES.read_text(), **{path: value})
        message = str(caught.exception)
        self.assertIn(path, message)
        self.assertEqual(message, "\n".join(lines[1:]))
        return message

    def test_invalid_values_raise_value_error_naming_the_field(self):
        self.assertIn("-5", self.assert_same_error_as_cli("gains.kps", -5))
        self.assertIn("1e+308", self.assert_same_error_as_cli("gains.kps", 1e308))

    def test_invalid_text_names_line_and_field(self):
        text = PADDLES.read_text().replace("kps: 600", "kps: nan")
        with self.assertRaises(ValueError) as caught:
            teleop.analyze(text)
        self.assertRegex(str(caught.exception), r"<text>:\d+:\d+: gains\.kps: must be finite")
        with self.assertRaises(ValueError) as caught:
            teleop.analyze(PADDLES, **{"gains.kpx": 1})
        self.assertIn("gains.kpx", str(caught.exception))


class MaxStiffness(unittest.TestCase):
    # A haptic wall on the master alone (no human, master not coupled: its gains are 0): mass m,
    # damping b, a spring K through a zero-order hold at period T. With a = exp(-bT/m) the
    # characteristic polynomial is z^2 + a1 z + a0 with
    #   a0 = a + (K/b) ((m/b)(1 - a) - aT),
    # and Jury's conditions reduce to a0 < 1 (the others hold with margin here), so
    #   K_max = b (1 - a) / ((m/b)(1 - a) - aT)  ->  2b/T as T -> 0 (Colgate-Schenkel).
    WALL = """
        sample_rate_hz: 1000
        master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } }
        slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } }
        gains { kps: 1000 kds: 6 }
        human { none {} }
        analysis { stiffness_tolerance_N_per_m: 0.01 }
    """

    @staticmethod
    def closed_form(m, b, rate_hz):
        t = 1.0 / rate_hz
        a = math.exp(-b * t / m)
        return b * (1.0 - a) / ((m / b) * (1.0 - a) - a * t)

    def test_master_wall_matches_the_closed_form(self):
        rates = [250.0, 1000.0, 4000.0]
        doc = teleop.max_stiffness(self.WALL, "master", rates_hz=rates)
        self.assertEqual(doc["side"], "master")
        self.assertEqual([l["sample_rate_hz"] for l in doc["limits"]], rates)
        for limit in doc["limits"]:
            rate = limit["sample_rate_hz"]
            expected = self.closed_form(0.040, 0.41, rate)
            self.assertAlmostEqual(limit["max_stable_stiffness_N_per_m"], expected, delta=0.01,
                                   msg=f"{rate} Hz")
            # Colgate-Schenkel's passivity bound b > KT/2: K < 2b/T.
            self.assertAlmostEqual(limit["passivity_limit_N_per_m"], 2 * 0.41 * rate, places=6)

    def test_agrees_with_the_cli_json(self):
        _, out, _ = run_cli("analyze", PADDLES, "--max-stiffness", "slave", "--rates",
                            "250,500", "--sweep", "gains.kds=1:3:1", "--json", expect=[0])
        py = teleop.max_stiffness(PADDLES.read_text(), "slave", rates_hz=[250, 500],
                                  sweep=("gains.kds", 1, 3, 1))
        self.assertEqual(without_effort(py), without_effort(json.loads(out)))
        self.assertEqual(len(py["limits"]), 6)  # 2 rates x kds = 1, 2, 3
        self.assertEqual(py["swept"], "gains.kds")
        again = teleop.max_stiffness(PADDLES, "slave", rates_hz=[250, 500], sweep="gains.kds=1:3:1")
        self.assertEqual(without_effort(again), without_effort(py))

    def test_paper_fig6_range(self):
        # Abbott-Okamura Fig. 6: T = 0.002 s, Kp = 800 N/m, Kd = 6 Ns/m; the worst-case user's
        # eigenvalues reach the stability boundary as K_sVF rises from 500 to 5500 N/m.
        doc = teleop.max_stiffness(PADDLES, "slave", **{"gains.kpm": 800, "gains.kps": 800,
                                                        "gains.kdm": 6, "gains.kds": 6})
        k = doc["limits"][0]["max_stable_stiffness_N_per_m"]
        self.assertEqual(doc["limits"][0]["sample_rate_hz"], 500)
        self.assertGreater(k, 500.0)
        self.assertLess(k, 5500.0)

    def test_bad_arguments(self):
        with self.assertRaisesRegex(ValueError, "'slave' or 'master'"):
            teleop.max_stiffness(PADDLES, "left")
        with self.assertRaisesRegex(ValueError, "not positive"):
            teleop.max_stiffness(PADDLES, "slave", rates_hz=[0])
        with self.assertRaisesRegex(ValueError, "STEP > 0"):
            teleop.max_stiffness(PADDLES, "slave", sweep="gains.kds=1:3:0")
        with self.assertRaisesRegex(ValueError, "gains.kps"):
            teleop.max_stiffness(PADDLES, "slave", **{"gains.kps": -5})


class ForceLoop(unittest.TestCase):
    def test_agrees_with_the_cli_json(self):
        path = SOURCE / "examples" / "force_loop.textproto"
        _, out, _ = run_cli("analyze", path, "--force-loop", "--json", expect=[0, 3, 4])
        self.assertEqual(teleop.analyze_force_loop(path), json.loads(out))
        with self.assertRaisesRegex(ValueError, "analyze_force_loop"):
            teleop.analyze(path)


class Simulate(unittest.TestCase):
    def test_same_series_as_the_cli_csv(self):
        with tempfile.TemporaryDirectory() as tmp:
            out = pathlib.Path(tmp) / "run.csv"
            run_cli("simulate", STABLE_SCENE, "--duration", "1", "--out", out, expect=[0])
            cli = read_csv(out)
        py = teleop.simulate(STABLE_SCENE, **{"scene.duration_s": 1})
        self.assertEqual(set(py) - {"summary"}, set(cli))
        for name, values in cli.items():
            np.testing.assert_array_equal(py[name], values, err_msg=name)
        self.assertEqual(len(py["time_s"]), 500)  # 1 s at 500 Hz
        self.assertEqual(py["summary"]["steps"], 500)
        self.assertFalse(py["summary"]["oscillation"]["detected"])

    def test_steady_state_force_is_stiffness_times_penetration(self):
        # Ideal devices, a fixed human pushing F* through its stiffness k_h, the slave against
        # tissue (k_e at p), no fixtures. At rest: F_h = F* - k_h x_m = Kp (x_m - x_s) (master)
        # and Kp (x_m - x_s) = k_e (x_s - p) = F_e (slave): two linear equations.
        kp, ke, p, kh, push = 600.0, 2000.0, 0.004, 70.0, 2.0
        scene = f"""
            sample_rate_hz: 1000
            master {{ device {{ mass_kg: 0.040 damping_Ns_per_m: 0.41 }} }}
            slave {{ device {{ mass_kg: 0.036 damping_Ns_per_m: 0.49 }} }}
            gains {{ kpm: {kp} kps: {kp} kdm: 2 kds: 2 }}
            human {{ fixed {{ mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: {kh} }} }}
            scene {{
              duration_s: 4 ideal: true
              human_force {{ constant {{ force_N: {push} }} }}
              environment {{ tissue {{ stiffness_N_per_m: {ke} position_m: {p} }} }}
            }}
        """
        r = teleop.simulate(scene)
        a = np.array([[kh + kp, -kp], [kp, -(kp + ke)]])
        xm, xs = np.linalg.solve(a, [push, -ke * p])
        self.assertGreater(xs, p)  # in contact
        penetration = r["slave_position_m"][-1] - p
        self.assertAlmostEqual(penetration, xs - p, delta=1e-6)
        self.assertAlmostEqual(r["master_position_m"][-1], xm, delta=1e-6)
        self.assertAlmostEqual(r["environment_force_N"][-1], ke * penetration, delta=1e-6)
        self.assertAlmostEqual(r["environment_force_N"][-1], ke * (xs - p), delta=2e-3)

    def test_bad_scene(self):
        with self.assertRaisesRegex(ValueError, "scene.duration_s"):
            teleop.simulate(STABLE_SCENE, **{"scene.duration_s": -1})


class Session(unittest.TestCase):
    DURATION_S = 2.0
    RATE_HZ = 500.0

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        tmp = pathlib.Path(cls.tmp.name)
        cls.mcap = tmp / "run.mcap"
        cls.csv = tmp / "run.csv"
        for out in (cls.mcap, cls.csv):
            run_cli("simulate", STABLE_SCENE, "--duration", cls.DURATION_S, "--out", out,
                    expect=[0])
        cls.session = teleop.open_session(cls.mcap)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_one_message_per_control_cycle(self):
        cycles = round(self.DURATION_S * self.RATE_HZ)
        for topic in ("/master/cycle", "/slave/cycle"):
            ch = self.session["channels"][topic]
            self.assertEqual(len(ch["position_m"]), cycles, topic)
            np.testing.assert_array_equal(ch["sequence"], np.arange(1, cycles + 1))
            period_ns = round(1e9 / self.RATE_HZ)
            np.testing.assert_array_equal(np.diff(ch["sample_time_ns"]), period_ns)
            np.testing.assert_array_equal(ch["publish_time_ns"], ch["sample_time_ns"])
            np.testing.assert_allclose(np.diff(ch["time_s"]), 1.0 / self.RATE_HZ, rtol=1e-9)
            self.assertTrue(np.all(np.diff(ch["log_time_ns"].astype(np.int64)) >= 0))
            self.assertEqual(ch["position_m"].dtype, np.float64)
            modes = self.session["enums"][topic]["mode"]
            self.assertEqual({modes[int(m)] for m in np.unique(ch["mode"])}, {"ENGAGED"})

    def test_positions_are_the_simulated_ones(self):
        # Cycle k is what each law sensed at sample k: the CSV's *_sensed_m of row k.
        rows = read_csv(self.csv)
        for side in ("master", "slave"):
            ch = self.session["channels"][f"/{side}/cycle"]
            np.testing.assert_array_equal(ch["position_m"], rows[f"{side}_sensed_m"])
        # The slave's command is F_as, the master's -F_am (docs/architecture.md §2.1).
        np.testing.assert_array_equal(self.session["channels"]["/slave/cycle"]["command_N"],
                                      rows["slave_force_N"])
        np.testing.assert_array_equal(self.session["channels"]["/master/cycle"]["command_N"],
                                      0.0 - rows["master_force_N"])

    def test_configuration_reports_alarms_and_changes(self):
        s = self.session
        self.assertIn("sample_rate_hz: 500", s["config_text"])
        self.assertIn("stiffness_N_per_m: 1500", s["config_text"])
        self.assertEqual(s["library"], f"teleop {teleop.__version__}")
        self.assertEqual(len(s["reports"]), 1)
        self.assertEqual(s["reports"][0]["verdict"], "stable")
        self.assertEqual(s["alarms"], [])
        self.assertEqual(s["parameter_changes"], [])
        tel = s["channels"]["/slave/telemetry"]
        self.assertEqual(len(tel["loop.period_s"]), round(self.DURATION_S * self.RATE_HZ / 20))
        np.testing.assert_allclose(tel["loop.period_s"], 1.0 / self.RATE_HZ)

    def test_missing_file(self):
        with self.assertRaises(FileNotFoundError):
            teleop.open_session(pathlib.Path(self.tmp.name) / "none.mcap")
        with self.assertRaises(RuntimeError):
            teleop.open_session(self.csv)  # not MCAP


class DescriptorSet(unittest.TestCase):
    def test_descriptor_set_holds_every_schema(self):
        # protoc decodes the set with descriptor.proto: the session's message types are in it.
        desc = pathlib.Path(os.environ["TELEOP_DESCRIPTOR_SET"])
        p = subprocess.run(["protoc", "--decode=google.protobuf.FileDescriptorSet",
                            "google/protobuf/descriptor.proto"], input=desc.read_bytes(),
                           capture_output=True, check=True)
        text = p.stdout.decode()
        for name in ("teleop/v1/telemetry.proto", "teleop/v1/config.proto",
                     "teleop/v1/supervisor.proto", "foxglove/Log.proto",
                     'name: "CycleRecord"', 'name: "SystemConfig"'):
            self.assertIn(name, text)


if __name__ == "__main__":
    unittest.main()

#!/usr/bin/env python3
"""Abbott & Okamura, Fig. 7, from Python: the largest stable slave fixture stiffness against
the sample rate, K_p = 600 N/m and K_d = 2 Ns/m on the haptic paddles.

    python3 examples/python/fig7.py                 # fig7.png (matplotlib), else fig7.csv
    python3 examples/python/fig7.py --csv fig7.csv  # the table only
    python3 examples/python/fig7.py --png fig7.png

Needs the module `teleop` on the path (installed by the package, or PYTHONPATH=build/python)
and numpy; the plot needs matplotlib (Debian python3-matplotlib). docs/python.md walks
through it.
"""

# %% Setup
import argparse
import csv
import pathlib
import sys

import numpy as np

import teleop

HERE = pathlib.Path(__file__).resolve().parent
# The paper's paddles (section 4.1) with Fig. 7's gains, as shipped in the examples.
DEFAULT_CONFIG = HERE.parent / "paddles.textproto"
# Sample rates, Hz: below about 250 Hz this loop is unstable without any fixture (shown).
RATES_HZ = [200, 250, 300, 400, 500, 600, 700, 800, 1000, 1250, 1500, 2000]

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("--config", type=pathlib.Path, default=DEFAULT_CONFIG)
parser.add_argument("--csv", type=pathlib.Path, help="write the table here (no plot)")
parser.add_argument("--png", type=pathlib.Path, help="write the plot here (needs matplotlib)")
args = parser.parse_args()

# %% The prediction: the worst case over the human band, and two users inside it.
# Fig. 7's gains: symmetric position-position control, K_p = 600 N/m, K_d = 2 Ns/m.
gains = {"gains.kpm": 600, "gains.kps": 600, "gains.kdm": 2, "gains.kds": 2}
band = teleop.max_stiffness(args.config, "slave", rates_hz=RATES_HZ, **gains)
# The paper's small and large users (user_S, user_L) measured their own fingers; here the
# band's lower and upper corners at a 5 N grip (examples/paddles.textproto's default band).
USERS = {
    "small": {"human.fixed.mass_kg": 0.003, "human.fixed.damping_Ns_per_m": 1.0,
              "human.fixed.stiffness_N_per_m": 100},
    "large": {"human.fixed.mass_kg": 0.012, "human.fixed.damping_Ns_per_m": 3.25,
              "human.fixed.stiffness_N_per_m": 325},
}
users = {name: teleop.max_stiffness(args.config, "slave", rates_hz=RATES_HZ, **gains, **h)
         for name, h in USERS.items()}


def limits(doc):
    return np.array([np.nan if l["max_stable_stiffness_N_per_m"] is None
                     else l["max_stable_stiffness_N_per_m"] for l in doc["limits"]])


rates = np.array([l["sample_rate_hz"] for l in band["limits"]])
k_band = limits(band)
k_small, k_large = limits(users["small"]), limits(users["large"])
# A rate with no limit: the teleoperator is unstable without any fixture there.
no_limit = {l["sample_rate_hz"]: l.get("reason", "") for l in band["limits"]
            if l["max_stable_stiffness_N_per_m"] is None}

# %% The paper's observations, checked on the numbers
has = ~np.isnan(k_band)
# "the stiffness of the FRVF goes up with sampling rate"
rises = bool(np.all(np.diff(k_band[has]) > 0))
# "the stability of the slave FRVF is independent of the user" (roughly: both users' limits)
fast = has & (rates >= 500)
spread = float(np.max(np.abs(k_small[fast] - k_large[fast]) / k_band[fast]))
print(f"limit rises with the sample rate: {rises}; small vs large user from 500 Hz: within "
      f"{100 * spread:.1f} %")
for r, kb, ks, kl in zip(rates, k_band, k_small, k_large):
    print(f"  {r:6g} Hz  band {kb:8.1f} N/m  small user {ks:8.1f} N/m  large user {kl:8.1f} N/m"
          + (f"  ({no_limit[r]})" if r in no_limit else ""))

# %% Output: a PNG with matplotlib, else (or with --csv) a CSV table.
columns = ["sample_rate_hz", "max_stable_stiffness_N_per_m", "small_user_N_per_m",
           "large_user_N_per_m"]
plt = None
if args.csv is None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not found (Debian: python3-matplotlib): writing a CSV instead")
if plt is None:
    out = args.csv or pathlib.Path("fig7.csv")
    with open(out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for row in zip(rates, k_band, k_small, k_large):
            w.writerow([repr(float(v)) for v in row])
    print(f"wrote {out}")
    sys.exit(0)

fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=150)
ax.plot(rates, k_band, "o-", color="#1f77b4", label="predicted, worst human of the band")
# The two users where the band has a limit (the CSV has every rate).
ax.plot(rates[has], k_small[has], "v", color="#2ca02c", markersize=6,
        label="predicted, small user")
ax.plot(rates[has], k_large[has], "^", color="#d62728", markersize=6, markerfacecolor="none",
        label="predicted, large user")
ax.set_ylim(150, 15000)
if no_limit:
    # Rates with no stable fixture at all: shown on the axis, not dropped.
    ax.plot(list(no_limit), [180] * len(no_limit), "x", color="black", markersize=9,
            label="no stable fixture: the worst human's loop is\nunstable without one")
ax.set_xscale("log")
ax.set_yscale("log")
ax.set_xticks([200, 500, 1000, 2000])
ax.set_xticklabels(["200", "500", "1000", "2000"])
ax.set_yticks([200, 500, 1000, 2000, 5000, 10000])
ax.set_yticklabels(["200", "500", "1000", "2000", "5000", "10000"])
ax.minorticks_off()
ax.set_xlabel("sample rate (Hz)")
ax.set_ylabel("maximum stable slave fixture stiffness (N/m)")
ax.set_title("Slave fixture limit vs sample rate ($K_p$ = 600 N/m, $K_d$ = 2 Ns/m)\n"
             "Abbott & Okamura, Fig. 7 (prediction)", fontsize=10)
ax.grid(True, which="both", alpha=0.3)
ax.legend(loc="lower right", fontsize=8)
fig.tight_layout()
out = args.png or pathlib.Path("fig7.png")
fig.savefig(out)
print(f"wrote {out}")

// The conventions a user of any teleop program can count on (issue 17, "CLI conventions"):
// every program answers --version with the project's version (CMake's project(VERSION));
// `--option=value` means `--option value`, and a flag given a value it does not take is a usage
// error; --json output is one JSON document whose keys are all snake_case (no camelCase hump,
// units as written in the .proto: stiffness_N_per_m); the installed bash completion offers the
// commands and each command's options; each program has a man page made from its --help.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>

#include "tests/integration/cli_harness.hpp"

namespace teleop::test {
namespace {

const std::string kSource = TELEOP_SOURCE_DIR;
const std::string kLive = kSource + "/examples/live.textproto";

// Every key of `j` (recursively) that is not snake_case: a lower-case letter or digit directly
// followed by an upper-case one is a camelCase hump ("minDampingRatio"); upper-case letters
// may only start a unit ("force_N", "damping_Ns_per_m").
void collect_camel_keys(const nlohmann::json& j, const std::string& where,
                        std::vector<std::string>& bad) {
  static const std::regex hump("[a-z0-9][A-Z]");
  if (j.is_object()) {
    for (const auto& [k, v] : j.items()) {
      if (std::regex_search(k, hump)) bad.push_back(where + "." + k);
      collect_camel_keys(v, where + "." + k, bad);
    }
  } else if (j.is_array()) {
    for (const auto& v : j) collect_camel_keys(v, where + "[]", bad);
  }
}

std::vector<std::string> camel_keys(const std::string& json_text) {
  std::vector<std::string> bad;
  // One document (possibly indented), or one per line (launch --json).
  if (nlohmann::json::accept(json_text)) {
    collect_camel_keys(nlohmann::json::parse(json_text), "", bad);
    return bad;
  }
  std::istringstream lines(json_text);
  std::string line;
  while (std::getline(lines, line)) {
    if (line.empty()) continue;
    collect_camel_keys(nlohmann::json::parse(line), "", bad);
  }
  return bad;
}

TEST(CliVersion, EveryProgramPrintsTheProjectVersion) {
  for (const std::string& prog : {std::string(TELEOPCTL_PATH), std::string(MASTER_BIN),
                                  std::string(SLAVE_BIN), std::string(SUPERVISOR_BIN)}) {
    const CliResult r = run(prog + " --version");
    const std::string name = std::filesystem::path(prog).filename().string();
    EXPECT_EQ(r.exit_code, 0) << prog;
    EXPECT_EQ(r.out, name + " " + PROJECT_VERSION_TEXT + "\n") << prog;
  }
}

TEST(CliOptionEquals, AnOptionsValueAfterAnEqualsSignMeansTheSame) {
  const CliResult spaced = teleopctl("analyze " + kLive + " --max-stiffness slave --json", false);
  const CliResult equals = teleopctl("analyze " + kLive + " --max-stiffness=slave --json", false);
  ASSERT_EQ(spaced.exit_code, 0) << spaced.out;
  EXPECT_EQ(equals.exit_code, 0) << equals.out;
  const nlohmann::json a = nlohmann::json::parse(spaced.out);
  const nlohmann::json b = nlohmann::json::parse(equals.out);
  // The same limit from the same file (the timing fields aside).
  EXPECT_EQ(a.dump().size() > 0, true);
  EXPECT_EQ(a["limits"].dump(), b["limits"].dump()) << spaced.out << "\n" << equals.out;

  const CliResult set_spaced =
      teleopctl("analyze " + kLive + " --set slave.fixture.stiffness_N_per_m=1234 --json", false);
  const CliResult set_equals =
      teleopctl("analyze " + kLive + " --set=slave.fixture.stiffness_N_per_m=1234 --json", false);
  ASSERT_EQ(set_spaced.exit_code, set_equals.exit_code) << set_equals.out;
  EXPECT_EQ(nlohmann::json::parse(set_spaced.out)["min_damping_ratio"],
            nlohmann::json::parse(set_equals.out)["min_damping_ratio"]);
}

TEST(CliOptionEquals, AFlagGivenAValueItDoesNotTakeIsAUsageError) {
  const CliResult r = teleopctl("analyze " + kLive + " --json=yes");
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("--json takes no value"), std::string::npos) << r.out;
  const CliResult d = run(std::string(SUPERVISOR_BIN) + " " + kLive + " --no-record=1");
  EXPECT_EQ(d.exit_code, 2) << d.out;
  EXPECT_NE(d.out.find("--no-record takes no value"), std::string::npos) << d.out;
  const CliResult m = run(std::string(MASTER_BIN) + " " + kLive + " --set");
  EXPECT_EQ(m.exit_code, 2) << m.out;
  EXPECT_NE(m.out.find("--set needs a value"), std::string::npos) << m.out;
}

TEST(CliJson, EveryJsonOutputHasSnakeCaseKeysOnly) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("teleop-cli-json-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string scene = kSource + "/examples/scenes/paddles_slave_fixture_stable.textproto";
  for (const std::string& args :
       {"analyze " + kLive + " --json", "analyze " + kLive + " --max-stiffness=slave --json",
        "analyze " + kLive + " --max-stiffness=slave --sweep=gains.kds=1:2:1 --json",
        "simulate " + scene + " --duration=0.2 --json",
        "keygen " + (dir / "k").string() + " --json"}) {
    const CliResult r = teleopctl(args, false);
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.out;
    std::vector<std::string> bad;
    ASSERT_NO_THROW(bad = camel_keys(r.out)) << args << "\n" << r.out;
    EXPECT_TRUE(bad.empty()) << args << ": " << ::testing::PrintToString(bad);
  }
  const nlohmann::json key =
      nlohmann::json::parse(teleopctl("keygen " + (dir / "k2").string() + " --json", false).out);
  // A Z85 CURVE public key is 40 characters; the files are where the JSON says.
  EXPECT_EQ(key["public_key"].get<std::string>().size(), 40U);
  EXPECT_TRUE(std::filesystem::exists(key["secret_key_file"].get<std::string>()));
  EXPECT_TRUE(std::filesystem::exists(key["public_key_file"].get<std::string>()));
  std::filesystem::remove_all(dir);
}

// Findings of a new user (issue 17, "Smaller"): a plot name that is not SVG, a plot the
// analysis does not have, and a force-loop file analysed as a teleoperator are refused with what
// to do instead; replay --resimulate's exit code follows the analyser's verdict.
TEST(CliRefusals, PlotsAreSvgAndOnlyWhereThereIsOne) {
  const std::string scene = kSource + "/examples/scenes/paddles_slave_fixture_stable.textproto";
  for (const std::string& args :
       {"analyze " + kLive + " --plot /tmp/teleop-x.png",
        "simulate " + scene + " --plot=/tmp/teleop-x.png",
        "analyze " + kSource + "/examples/force_loop.textproto --force-loop --plot /tmp/x.svg"}) {
    const CliResult r = teleopctl(args);
    EXPECT_EQ(r.exit_code, 2) << args << "\n" << r.out;
    EXPECT_NE(r.out.find("--plot"), std::string::npos) << args << "\n" << r.out;
  }
  EXPECT_NE(teleopctl("analyze " + kLive + " --plot /tmp/teleop-x.png").out.find("rsvg-convert"),
            std::string::npos);
}

TEST(CliRefusals, AForceLoopFileAnalysedAsATeleoperatorSuggestsForceLoop) {
  const std::string file = kSource + "/examples/force_loop.textproto";
  const CliResult r = teleopctl("analyze " + file);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("--force-loop"), std::string::npos) << r.out;
  // And the analysis it suggests works on that file.
  EXPECT_EQ(teleopctl("analyze " + file + " --force-loop").exit_code, 0);
}

TEST(CliRefusals, ResimulateExitCodeFollowsTheVerdict) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("teleop-cli-resim-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string scene = kSource + "/examples/scenes/paddles_slave_fixture_stable.textproto";
  const std::string mcap = (dir / "s.mcap").string();
  // 0.1 s of motion: too short for the resimulation to see an oscillation, so only the
  // analyser's verdict can make the exit code non-zero (it was 0 for an unstable loop before).
  ASSERT_EQ(teleopctl("simulate " + scene + " --duration=0.1 --out=" + mcap, false).exit_code, 0);
  // The analyser's own verdicts on the scene's loop (analyze: 0 stable, 3 unstable), for the
  // recorded slave fixture and a far stiffer one; replay --resimulate must exit as analyze does.
  for (const std::string& set :
       {std::string(), std::string(" --set slave.fixture.stiffness_N_per_m=20000")}) {
    const int analyzed = teleopctl("analyze " + scene + set, false).exit_code;
    ASSERT_TRUE(analyzed == 0 || analyzed == 3) << set;
    const CliResult r = teleopctl("replay " + mcap + " --resimulate --json" + set, false);
    const nlohmann::json j = nlohmann::json::parse(r.out, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << r.out;
    EXPECT_EQ(j["resimulated"]["analysis"]["verdict"], analyzed == 0 ? "stable" : "unstable")
        << set;
    EXPECT_EQ(r.exit_code, analyzed) << set << "\n" << r.out;
  }
  // Both verdicts occur.
  EXPECT_EQ(teleopctl("analyze " + scene, false).exit_code, 0);
  EXPECT_EQ(teleopctl("analyze " + scene + " --set slave.fixture.stiffness_N_per_m=20000", false)
                .exit_code,
            3);
  std::filesystem::remove_all(dir);
}

// A command run on a terminal (script(1) gives it a pseudo-terminal): everything it printed.
std::string on_terminal(const std::string& args) {
  return run("script -qec \"" + std::string(TELEOPCTL_PATH) + " " + args + "\" /dev/null").out;
}

TEST(CliProgress, OnATerminalOnlyAndNeverInJson) {
  const std::string scene = kSource + "/examples/scenes/paddles_slave_fixture_stable.textproto";
  // On a terminal: the progress line, then erased (carriage return + erase line) before the
  // summary.
  const std::string text = on_terminal("simulate " + scene + " --duration=5");
  EXPECT_NE(text.find("simulate: "), std::string::npos) << text;
  EXPECT_NE(text.find("\r\033[K"), std::string::npos) << text;
  // --json on a terminal, and the text through a pipe: no progress line.
  EXPECT_EQ(on_terminal("simulate " + scene + " --duration=5 --json").find("simulate: "),
            std::string::npos);
  EXPECT_EQ(teleopctl("simulate " + scene + " --duration=5").out.find("simulate: "),
            std::string::npos);
  const std::string sweep =
      on_terminal("analyze " + kLive + " --max-stiffness=slave --sweep=gains.kds=1:3:1");
  EXPECT_NE(sweep.find("analyze --max-stiffness: "), std::string::npos) << sweep;
}

// What a command drew on a terminal: the percentages its progress line `label` showed, in
// order ("\r\033[K<label>:  37%" each), whether the line was then erased ("\r\033[K") and what
// came after it.
struct ProgressDrawn {
  std::vector<int> percents{};
  bool erased{false};
  std::string after{};
};

ProgressDrawn progress_drawn(const std::string& text, const std::string& label) {
  const std::string draw = "\r\033[K" + label + ": ";
  const std::string erase = "\r\033[K";
  ProgressDrawn d;
  std::size_t end = std::string::npos;
  for (std::size_t at = text.find(draw); at != std::string::npos; at = text.find(draw, end)) {
    at += draw.size();
    const std::size_t percent = text.find('%', at);
    if (percent == std::string::npos || percent > at + 3) break;
    d.percents.push_back(std::stoi(text.substr(at, percent - at)));
    end = percent + 1;
  }
  if (end == std::string::npos) return d;
  d.erased = text.compare(end, erase.size(), erase) == 0;
  d.after = text.substr(d.erased ? end + erase.size() : end);
  return d;
}

// On a terminal, the progress line of `label` is drawn, goes only forward within 0..100 %, and
// is erased before the result, which starts with `result`; with --json on a terminal and
// through a pipe there is none, and --json's output parses.
void expect_progress_on_a_terminal_only(const std::string& args, const std::string& label,
                                        const std::string& result) {
  const std::string text = on_terminal(args);
  const ProgressDrawn d = progress_drawn(text, label);
  ASSERT_FALSE(d.percents.empty()) << args << "\n" << text;
  EXPECT_TRUE(std::is_sorted(d.percents.begin(), d.percents.end())) << args << "\n" << text;
  EXPECT_GE(d.percents.front(), 0) << args;
  EXPECT_LE(d.percents.back(), 100) << args;
  EXPECT_TRUE(d.erased) << args << "\n" << text;
  EXPECT_EQ(d.after.rfind(result, 0), 0U) << args << "\n" << text;
  EXPECT_EQ(d.after.find(label + ": "), std::string::npos) << args << "\n" << text;

  const std::string json_text = on_terminal(args + " --json");
  EXPECT_EQ(json_text.find(label + ": "), std::string::npos) << args << " --json\n" << json_text;
  EXPECT_EQ(json_text.find('\033'), std::string::npos) << args << " --json\n" << json_text;
  EXPECT_TRUE(nlohmann::json::accept(json_text)) << args << " --json\n" << json_text;
  // Through a pipe (stderr with stdout): the result only.
  const CliResult piped = teleopctl(args);
  EXPECT_EQ(piped.out.find(label + ": "), std::string::npos) << args << "\n" << piped.out;
  EXPECT_EQ(piped.out.find('\033'), std::string::npos) << args << "\n" << piped.out;
  EXPECT_EQ(piped.out.rfind(result, 0), 0U) << args << "\n" << piped.out;
  const CliResult piped_json = teleopctl(args + " --json", false);
  EXPECT_TRUE(nlohmann::json::accept(piped_json.out)) << args << " --json\n" << piped_json.out;
}

// A 30 s session of the identification scene (10 MB: the passes over it take a noticeable
// part of a second), written once for the tests below, and a copy cut short at two thirds
// (a crash mid-session).
class CliProgressOnSessions : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = std::filesystem::temp_directory_path() /
           ("teleop-cli-progress-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
    const std::string scene = kSource + "/examples/scenes/identify_excitation.textproto";
    for (const char* out : {"session.mcap", "session.csv"}) {
      const CliResult r = teleopctl("simulate " + scene + " --duration=30 --out=" + file(out));
      ASSERT_EQ(r.exit_code, 0) << r.out;
    }
    std::filesystem::copy_file(file("session.mcap"), file("cut.mcap"));
    std::filesystem::resize_file(file("cut.mcap"),
                                 std::filesystem::file_size(file("session.mcap")) * 2 / 3);
  }
  static void TearDownTestSuite() { std::filesystem::remove_all(dir_); }
  static std::string file(const std::string& name) { return (dir_ / name).string(); }

 private:
  static inline std::filesystem::path dir_{};
};

TEST_F(CliProgressOnSessions, ReplayRecoverShowsItsProgressOnATerminalOnly) {
  const std::string out = file("recovered.mcap");
  expect_progress_on_a_terminal_only("replay " + file("cut.mcap") + " --recover " + out,
                                     "replay --recover", file("cut.mcap") + ": kept ");
  // What it wrote (each run the same) is a whole session.
  EXPECT_EQ(teleopctl("replay " + out, false).exit_code, 0);
}

TEST_F(CliProgressOnSessions, IdentifyShowsItsProgressOnATerminalOnly) {
  expect_progress_on_a_terminal_only("identify " + file("session.mcap"), "identify",
                                     "identified master device: ");
  expect_progress_on_a_terminal_only("identify " + file("session.csv") + " --device slave",
                                     "identify", "identified slave device: ");
}

TEST_F(CliProgressOnSessions, ReplayResimulateShowsItsProgressOnATerminalOnly) {
  expect_progress_on_a_terminal_only("replay " + file("session.mcap") + " --resimulate",
                                     "replay --resimulate",
                                     file("session.mcap") + ": the recorded master motion");
}

// The completion script as bash runs it: COMP_WORDS/COMP_CWORD in, COMPREPLY out.
std::string complete(const std::string& words, int cword) {
  const std::string bin_dir = std::filesystem::path(TELEOPCTL_PATH).parent_path().string();
  const std::string script = kSource + "/deploy/bash-completion/teleopctl";
  return run("PATH='" + bin_dir + "':\"$PATH\" bash -c 'source " + script + "; COMP_WORDS=(" +
             words + "); COMP_CWORD=" + std::to_string(cword) +
             "; _teleopctl; printf \"%s\\n\" \"${COMPREPLY[@]}\"'")
      .out;
}

TEST(CliCompletion, OffersTheCommandsAndEachCommandsOptions) {
  EXPECT_EQ(complete("teleopctl an", 1), "analyze\n");
  EXPECT_EQ(complete("teleopctl re", 1), "replay\nrelay\n");  // in the usage's order
  // Options come from the command's own --help.
  EXPECT_EQ(complete("teleopctl analyze --max-st", 2), "--max-stiffness\n");
  EXPECT_EQ(complete("teleopctl set --dry", 2), "--dry-run\n");
  EXPECT_EQ(complete("teleopctl node 127.0.0.1:5562 eng", 3), "engage\n");
}

#if defined(TELEOP_MAN_PAGES)
TEST(CliManPages, EachProgramHasOneMadeFromItsHelp) {
  const std::string man_dir = MAN_DIR;
  ASSERT_FALSE(man_dir.empty());
  for (const char* prog : {"teleopctl", "teleop-master", "teleop-slave", "teleop-supervisor"}) {
    std::ifstream in(man_dir + "/" + prog + ".1");
    ASSERT_TRUE(in) << prog;
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_NE(text.str().find(".TH"), std::string::npos) << prog;
    EXPECT_NE(text.str().find(PROJECT_VERSION_TEXT), std::string::npos) << prog;
  }
  std::ifstream in(man_dir + "/teleopctl.1");
  std::stringstream text;
  text << in.rdbuf();
  // Every command's help is in teleopctl(1), down to its options.
  for (const char* cmd : {"analyze", "simulate", "launch", "replay", "estop", "status"}) {
    EXPECT_NE(text.str().find(std::string(".SS ") + cmd), std::string::npos) << cmd;
  }
  EXPECT_NE(text.str().find("max-stiffness"), std::string::npos);
}
#endif

}  // namespace
}  // namespace teleop::test

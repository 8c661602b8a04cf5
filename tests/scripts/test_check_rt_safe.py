#!/usr/bin/env python3
"""Hand-made snippets for scripts/check_rt_safe.py (run: python3 this_file)."""
import os
import sys
import tempfile
import textwrap
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts"))
import check_rt_safe as rt  # noqa: E402


def run(files):
    """(marked count, problems) of the snippets {relative path: source} in a temporary tree."""
    with tempfile.TemporaryDirectory() as d:
        paths = []
        for rel, text in files.items():
            p = os.path.join(d, rel)
            os.makedirs(os.path.dirname(p), exist_ok=True)
            with open(p, "w", encoding="utf-8") as f:
                f.write(textwrap.dedent(text))
            paths.append(p)
        marked, problems = rt.check(paths)
        return marked, [p.replace(d + os.sep, "") for p in problems]


HEADER = """\
    #pragma once
    class Law {
     public:
      TELEOP_RT [[nodiscard]] double step(double x) noexcept;
      TELEOP_RT void reset() noexcept { state_ = 0.0; }
     private:
      double state_{0.0};
    };
    """


class RtCheck(unittest.TestCase):
    def test_clean_functions_pass(self):
        src = "#include \"law.hpp\"\ndouble Law::step(double x) noexcept { return 2.0 * x; }\n"
        marked, problems = run({"a/law.hpp": HEADER, "a/law.cpp": src})
        self.assertEqual(problems, [])
        self.assertEqual(marked, 2)

    def test_a_marked_function_without_noexcept_fails_naming_it(self):
        header = HEADER.replace("void reset() noexcept", "void reset()")
        src = "double Law::step(double x) noexcept { return x; }\n"
        _, problems = run({"a/law.hpp": header, "a/law.cpp": src})
        self.assertEqual(problems, ["a/law.hpp:5: Law::reset: an RT function must be noexcept"])

    def test_forbidden_calls_in_an_out_of_line_body_fail_with_their_line(self):
        src = ("double Law::step(double x) noexcept {\n"
               "  auto* p = new double(x);\n"
               "  std::string s = \"no\";\n"
               "  spdlog::info(\"{}\", x);\n"
               "  log_.push_back(x);\n"
               "  m_.lock();\n"
               "  if (x < 0) throw 1;\n"
               "  return *p;\n"
               "}\n")
        _, problems = run({"a/law.hpp": HEADER, "a/law.cpp": src})
        self.assertEqual(problems, [
            "a/law.cpp:2: Law::step: allocates (new)",
            "a/law.cpp:3: Law::step: allocates (std::string by value)",
            "a/law.cpp:4: Law::step: logs (spdlog)",
            "a/law.cpp:5: Law::step: may allocate (push_back)",
            "a/law.cpp:6: Law::step: takes a lock (.lock())",
            "a/law.cpp:7: Law::step: throws",
        ])

    def test_comments_strings_and_references_are_not_calls(self):
        src = ("// new, malloc and throw in a comment are fine\n"
               "double Law::step(double x) noexcept {\n"
               "  const char* why = \"throw new printf\";  /* new */\n"
               "  const std::vector<double>& v = table();\n"
               "  return x + v[0] + (why != nullptr);\n"
               "}\n")
        _, problems = run({"a/law.hpp": HEADER, "a/law.cpp": src})
        self.assertEqual(problems, [])

    def test_an_inline_body_is_checked_in_place(self):
        header = HEADER.replace("{ state_ = 0.0; }", "{ state_ = static_cast<double>(malloc(8) != nullptr); }")
        src = "double Law::step(double x) noexcept { return x; }\n"
        _, problems = run({"a/law.hpp": header, "a/law.cpp": src})
        self.assertEqual(problems, ["a/law.hpp:5: Law::reset: allocates (malloc)"])

    def test_a_marked_declaration_without_a_body_anywhere_fails(self):
        _, problems = run({"a/law.hpp": HEADER})
        self.assertEqual(problems, ["a/law.hpp:4: Law::step: no definition found in a to check"])

    def test_pure_virtual_needs_no_body_but_still_noexcept(self):
        header = ("class Device {\n public:\n"
                  "  TELEOP_RT virtual int read(int& s) noexcept = 0;\n"
                  "  TELEOP_RT virtual int write(int c) = 0;\n"
                  "};\n")
        _, problems = run({"a/device.hpp": header})
        self.assertEqual(problems, ["a/device.hpp:4: Device::write: an RT function must be noexcept"])

    def test_the_class_of_a_nested_struct_names_the_body(self):
        header = ("class Core {\n  struct Entry final : Handler {\n"
                  "    TELEOP_RT void on_enter(int m) noexcept override;\n  };\n};\n")
        src = "void Core::Entry::on_enter(int m) noexcept { printf(\"%d\", m); }\n"
        _, problems = run({"a/core.hpp": header, "a/core.cpp": src})
        self.assertEqual(problems, ["a/core.cpp:1: Entry::on_enter: does I/O (printf)"])


if __name__ == "__main__":
    unittest.main()

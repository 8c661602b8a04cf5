#!/usr/bin/env python3
"""Hand-made snippets for scripts/check_function_length.py (run: python3 this_file)."""
import contextlib
import io
import os
import sys
import tempfile
import textwrap
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts"))
import check_function_length as cfl  # noqa: E402


def found(src):
    """{name: (first line, line count)} of every function in src."""
    out = {}
    for fn in cfl.functions_in(textwrap.dedent(src)):
        assert fn.name not in out, f"{fn.name} twice"
        out[fn.name] = (fn.start, fn.lines)
    return out


def body(n, indent="  "):
    return "".join(f"{indent}x += {k};\n" for k in range(n))


class Functions(unittest.TestCase):
    def test_free_function_counted_from_signature_to_closing_brace(self):
        src = "// comment above, not counted\nint f(int x) {\n" + body(5) + "  return x;\n}\n"
        self.assertEqual(found(src), {"f": (2, 8)})

    def test_lambdas_in_a_body_count_for_the_function(self):
        src = ("void NodeApp::start() {\n"
               "  auto a = [this] {\n" + body(10, "    ") + "  };\n"
               "  std::thread t([&]() mutable -> int {\n" + body(10, "    ") + "    return 1;\n"
               "  });\n"
               "  run([] { return 2; }, [](int y) noexcept { return y; });\n"
               "}\n")
        self.assertEqual(found(src), {"NodeApp::start": (1, 28)})

    def test_out_of_class_member_with_a_multi_line_signature(self):
        src = """\
            namespace teleop::record {
            template <typename T>
            [[nodiscard]] std::vector<T> McapReader::scan(bool recovering,
                                                          const Options& options) const noexcept {
              if (recovering) {
                return {};
              }
              return {T{1}, T{2}};
            }
            }  // namespace teleop::record
            """
        self.assertEqual(found(src), {"McapReader::scan": (2, 8)})

    def test_constructor_with_an_initialiser_list(self):
        src = """\
            Rig::Rig(const Config& config,
                     Link& link)
                : config_(config),
                  table_{1, 2, 3},
                  callback_([this](int x) {
                    return x + 1;
                  }),
                  name_{"{ not a body"} {
              start();
            }
            Other::Other() : a_{1}, b_{2} {}
            """
        self.assertEqual(found(src), {"Rig::Rig": (1, 10), "Other::Other": (11, 1)})

    def test_classes_namespaces_and_enums_are_not_functions(self):
        src = ("namespace a {\nnamespace {\n"
               "struct alignas(64) Impl final : public Base<int> {\n"
               "  Impl() = default;\n"
               "  int get() const { return v_; }\n"
               "  void set(int v) {\n    v_ = v;\n  }\n"
               "  struct Inner {\n    void f() {}\n  };\n"
               "  enum class Mode : std::uint8_t { kA, kB };\n"
               "  std::array<int, 3> table_{1, 2, 3};\n"
               "  int v_ = 0;\n"
               "};\n"
               "}  // namespace\n}  // namespace a\n")
        self.assertEqual(found(src), {"Impl::get": (5, 1), "Impl::set": (6, 3),
                                      "Impl::Inner::f": (10, 1)})

    def test_initialiser_data_is_not_a_function(self):
        rows = "".join(f'    {{"key{k}", {{{k}, {k}}}}},\n' for k in range(150))
        src = ("const std::map<std::string, std::pair<int, int>> kTable = {\n" + rows + "};\n"
               "static const Options kDefaults{\n    .a = 1,\n    .b = {2, 3},\n};\n"
               "std::vector<int> g_values{\n" + "    1,\n" * 150 + "};\n"
               "int f(const Options& o = {}, std::vector<int> v = {1, 2}) { return 0; }\n")
        self.assertEqual(found(src), {"f": (src.count("\n"), 1)})

    def test_a_lambda_in_data_or_at_namespace_scope_is_a_function_of_its_own(self):
        src = """\
            const auto kHandler = [](int x) {
              return x * 2;
            };
            const std::map<std::string, Handler> kHandlers{
                {"a", [](const Args& a) {
                   return run(a);
                 }},
            };
            struct Pair {
              Socket client{[this] {
                Socket c(ctx);
                return c;
              }()};
            };
            """
        self.assertEqual(found(src), {"kHandler (lambda)": (1, 3),
                                      "kHandlers::(lambda)": (5, 3),
                                      "Pair::client::(lambda)": (10, 4)})

    def test_names_of_operators_destructors_templates_and_trailing_returns(self):
        src = """\
            bool Foo::operator==(const Foo& o) const { return a == o.a; }
            double operator()(double x) { return x; }
            Foo::~Foo() { stop(); }
            auto make() -> std::unique_ptr<Foo> { return nullptr; }
            template <typename Body, typename = std::enable_if_t<true>>
            std::function<void()> keep_running(Body body) {
              return [body] { body(); };
            }
            decltype(auto) get(int& x) { return (x); }
            Foo::operator bool() const { return ok_; }
            extern "C" void on_interrupt(int) { g = 1; }
            extern "C" {
            int c_api(void) { return 0; }
            }
            template <typename T>
            void Outer<T>::name(T x) { use(x); }
            template <>
            int twice<int>(int x) { return 2 * x; }
            const auto kGeneric = []<class T>(T x) { return x; };
            """
        self.assertEqual(set(found(src)), {
            "Foo::operator==", "operator()", "Foo::~Foo", "make", "keep_running", "get",
            "Foo::operator bool", "on_interrupt", "c_api", "Outer::name", "twice",
            "kGeneric (lambda)"})
        self.assertEqual(found(src)["keep_running"], (5, 4))

    def test_braces_in_comments_literals_and_directives_are_ignored(self):
        src = ('#define OPEN {\n'
               '#define LONG_MACRO(x) \\\n  do { \\\n  } while (0)\n'
               'int f() {\n'
               '  const char* s = "}";  // }\n'
               '  /* } */ char c = \'}\';\n'
               '  auto r = R"json({"a": {}})json";\n'
               '  auto u = u8"}";\n'
               '  long n = 1\'000\'000;\n'
               '  return 0;\n'
               '}\n'
               'int g() { return \'{\'; }\n')
        self.assertEqual(found(src), {"f": (5, 8), "g": (13, 1)})


class CommandLine(unittest.TestCase):
    def run_main(self, *args):
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            status = cfl.main(list(args))
        return status, out.getvalue()

    def test_exit_status_and_exceptions(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "a.cpp")
            with open(path, "w") as f:
                f.write("namespace n {\nvoid longer() {\n" + body(10) + "}\n"
                        "void short_one() {}\n}\n")
            status, out = self.run_main("10", path)
            self.assertEqual(status, 1)
            self.assertIn(f"12 {path}:2 longer", out)
            self.assertNotIn("short_one", out)
            self.assertEqual(self.run_main("12", path)[0], 0)
            exceptions = os.path.join(d, "exceptions.txt")
            with open(exceptions, "w") as f:
                f.write(f"# being split elsewhere\n{path}:longer\n{path}:gone  # stale\n")
            status, out = self.run_main("--exceptions", exceptions, "10", path)
            self.assertEqual(status, 0)
            self.assertIn("known exception", out)
            self.assertIn(f"exception {path}:gone matches no function", out)


    def test_unbalanced_brackets_fail_the_file(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "a.cpp")
            with open(path, "w") as f:
                f.write("#ifdef A\nvoid f(int a) {\n#else\nvoid f() {\n#endif\n}\n")
            status, out = self.run_main("120", path)
            self.assertEqual(status, 1)
            self.assertIn(f"{path}:2: unbalanced bracket", out)


if __name__ == "__main__":
    unittest.main()

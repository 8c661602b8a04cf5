#!/usr/bin/env python3
"""Fails when a C++ function is longer than N lines (issue 16: none over 120 in common/ and
supervisor/).

    scripts/check_function_length.py [--exceptions FILE] N FILE...

A function's length is counted in physical lines from the first line of its declaration
(template header and attributes included, the comment above it not) to its closing brace,
everything in its body included: lambdas, local classes, blank and comment lines. What counts
as a function: free and member functions defined in or out of their class, constructors with
their initialiser lists, operators, and lambdas at namespace or class scope (a lambda in a
function is part of that function). Namespaces, classes, enums and braced initialisers (data
tables, member initialisers, default arguments) are not functions; a lambda inside a data
table is, on its own.

The source is tokenised (comments, string, character and raw-string literals and preprocessor
lines removed) and the braces are matched; it is not a full C++ parser: macros that expand to
declarations, and code that does not balance its brackets, can confuse it.

--exceptions FILE: known long functions, one `path:function` per line (`#` starts a comment),
reported but not failing; an entry that matches nothing is noted so the list can shrink.
The function name is the one printed in the report (`Class::member`, `free_function`, or
`name (lambda)`). Exit status 1 when a function not in the list is too long.
"""
import argparse
import re
import sys

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_NUMBER = re.compile(r"\.?[0-9](?:[eEpP][+-]|[0-9A-Za-z_.']|)*")
_PUNCT = [
    "->*", "<=>", "...", "<<=", ">>=", "::", "->", "==", "!=", "<=", ">=", "&&", "||", "++",
    "--", "+=", "-=", "*=", "/=", "%=", "&=", "|=", "^=", ".*",
]
_STRING_PREFIXES = {"R", "u8R", "uR", "UR", "LR", "u8", "u", "U", "L"}
_CLASS_KEYS = {"class", "struct", "union", "enum"}
# Tokens that may stand between a parameter list and the body.
_SPECIFIERS = {"const", "volatile", "mutable", "constexpr", "consteval", "noexcept",
               "override", "final", "&", "&&", "static", "try"}
_SPECIFIER_CALLS = {"noexcept", "throw", "requires", "__attribute__"}
_NOT_A_NAME_CALL = {"decltype", "alignas", "__attribute__", "__declspec", "noexcept",
                    "operator", "requires"}
_ACCESS = {"public", "private", "protected"}


class Token:
    __slots__ = ("text", "line")

    def __init__(self, text, line):
        self.text = text
        self.line = line

    def __repr__(self):
        return f"{self.text}@{self.line}"


def tokenize(src):
    """C++ tokens with their line numbers; literals become STR/CHR, no comments or directives."""
    tokens = []
    i, n, line = 0, len(src), 1
    at_line_start = True
    while i < n:
        c = src[i]
        if c == "\n":
            line += 1
            i += 1
            at_line_start = True
            continue
        if c in " \t\r\f\v":
            i += 1
            continue
        if c == "\\" and i + 1 < n and src[i + 1] == "\n":
            line += 1
            i += 2
            continue
        if c == "#" and at_line_start:  # preprocessor directive, with its continuations
            while i < n and src[i] != "\n":
                if src[i] == "\\" and i + 1 < n and src[i + 1] == "\n":
                    line += 1
                    i += 1
                elif src.startswith("/*", i):  # a block comment may carry the directive on
                    end = src.find("*/", i + 2)
                    end = n if end < 0 else end + 2
                    line += src.count("\n", i, end)
                    i = end
                    continue
                elif src.startswith("//", i):
                    while i < n and src[i] != "\n":
                        i += 1
                    break
                i += 1
            continue
        at_line_start = False
        if src.startswith("//", i):
            while i < n and src[i] != "\n":
                i += 1
            continue
        if src.startswith("/*", i):
            end = src.find("*/", i + 2)
            end = n if end < 0 else end + 2
            line += src.count("\n", i, end)
            i = end
            continue
        m = _IDENT.match(src, i)
        if m:
            word = m.group(0)
            j = m.end()
            if word in _STRING_PREFIXES and j < n and src[j] in "\"'":
                if word.endswith("R") and src[j] == '"':
                    start_line = line
                    paren = src.find("(", j)
                    delim = src[j + 1:paren]
                    end = src.find(")" + delim + '"', paren)
                    end = n if end < 0 else end + len(delim) + 2
                    line += src.count("\n", i, end)
                    tokens.append(Token("STR", start_line))
                    i = end
                    continue
                i = j  # an ordinary literal with an encoding prefix
                continue
            tokens.append(Token(word, line))
            i = j
            continue
        m = _NUMBER.match(src, i)
        if m:
            tokens.append(Token("NUM", line))
            i = m.end()
            continue
        if c in "\"'":
            j = i + 1
            while j < n and src[j] != c and src[j] != "\n":
                j += 2 if src[j] == "\\" else 1
            tokens.append(Token("STR" if c == '"' else "CHR", line))
            i = j + 1
            continue
        for p in _PUNCT:
            if src.startswith(p, i):
                tokens.append(Token(p, line))
                i += len(p)
                break
        else:
            tokens.append(Token(c, line))
            i += 1
    return tokens


def match_brackets(tokens):
    """Index of the matching bracket for each (), [], {} token; unbalanced ones stay unmatched."""
    pairs = {")": "(", "]": "[", "}": "{"}
    match = [-1] * len(tokens)
    stack = []
    for i, t in enumerate(tokens):
        if t.text in "([{" and len(t.text) == 1:
            stack.append(i)
        elif t.text in pairs and len(t.text) == 1:
            # Tolerate stray closers: unwind to the nearest opener of the same kind.
            k = len(stack) - 1
            while k >= 0 and tokens[stack[k]].text != pairs[t.text]:
                k -= 1
            if k >= 0:
                j = stack[k]
                del stack[k:]
                match[i], match[j] = j, i
    return match


class Function:
    def __init__(self, name, start, end, kind="function"):
        self.name, self.start, self.end, self.kind = name, start, end, kind

    @property
    def lines(self):
        return self.end - self.start + 1


class Parser:
    def __init__(self, src):
        self.t = tokenize(src)
        self.m = match_brackets(self.t)
        self.functions = []

    def unbalanced(self):
        """Line of the first bracket without a partner (None: all balanced)."""
        for i, t in enumerate(self.t):
            if self.m[i] < 0 and len(t.text) == 1 and t.text in "()[]{}":
                return t.line
        return None

    def text(self, i):
        return self.t[i].text if 0 <= i < len(self.t) else ""

    # --- declaration helpers -------------------------------------------------------------
    def top_level(self, start, end):
        """Indices in [start, end) at bracket depth 0 (groups reported by their opener only).

        Stops early with 'inside' when `end` lies within a group opened after `start`.
        """
        out = []
        i = start
        while i < end:
            out.append(i)
            if self.text(i) in ("(", "[", "{") and self.m[i] >= 0:
                if self.m[i] >= end:
                    return out, True
                i = self.m[i] + 1
            else:
                i += 1
        return out, False

    def skip_template_header(self, idx):
        """Drops `template <...>` headers and `[[...]]` attributes from the front of idx."""
        k = 0
        while k < len(idx):
            tx = self.text(idx[k])
            if tx == "template" and k + 1 < len(idx) and self.text(idx[k + 1]) == "<":
                depth, k = 0, k + 1
                while k < len(idx):
                    tx = self.text(idx[k])
                    depth += (tx == "<") - (tx == ">")
                    k += 1
                    if depth == 0:
                        break
            elif tx == "[" and self.text(idx[k] + 1) == "[":
                k += 1
            elif tx in ("export", "typedef", "inline", "friend"):
                k += 1
            else:
                break
        return idx[k:]

    def is_lambda_introducer(self, close):
        """True when the `]` at `close` ends a lambda capture list (not a subscript/attribute)."""
        open_ = self.m[close]
        if open_ < 0:
            return False
        before = self.text(open_ - 1)
        if before == "[" or self.text(close - 1) == "]":  # [[attribute]]
            return False
        if before in ("operator", "new", "delete", "]", ")", ">") or (
                _IDENT.fullmatch(before) and before not in ("return", "co_return", "co_yield")):
            return False
        return True

    def before_specifiers(self, brace, floor):
        """The token before `brace` once trailing return type and specifiers are passed over."""
        # A trailing return type: a depth-0 `->` between the declaration start and the brace.
        p = brace - 1
        while p > floor:
            tx = self.text(p)
            if tx in (")", "]", "}") and self.m[p] >= 0:
                p = self.m[p] - 1
                continue
            if tx == "->":
                break
            if tx in (";", "{", "=", ","):
                p = floor
                break
            p -= 1
        p = p - 1 if p > floor and self.text(p) == "->" else brace - 1
        while p > floor:
            tx = self.text(p)
            if tx in _SPECIFIERS:
                p -= 1
            elif tx == ")" and self.m[p] > 0 and self.text(self.m[p] - 1) in _SPECIFIER_CALLS:
                p = self.m[p] - 2
            else:
                break
        return p

    def lambda_at(self, brace, floor):
        """The index of the capture list's `[` when the `{` at `brace` opens a lambda, else -1."""
        p = self.before_specifiers(brace, floor)
        tx = self.text(p)
        if tx == "]":
            return self.m[p] if self.is_lambda_introducer(p) else -1
        if tx == ")" and self.m[p] > 0:
            q = self.m[p] - 1
            if self.text(q) == ">":  # []<class T>(...)
                q = self.before_angles(q, floor)
            if self.text(q) == "]" and self.is_lambda_introducer(q):
                return self.m[q]
        return -1

    def before_angles(self, close, floor=-1):
        """The token before the `<` matching the `>` at `close`."""
        q, depth = close, 0
        while q > floor:
            depth += (self.text(q) == ">") - (self.text(q) == "<")
            q -= 1
            if depth == 0:
                break
        return q

    def name_before(self, paren):
        """The (qualified) name written just before the `(` at `paren`."""
        q = paren - 1
        parts = []
        # operator@ / operator() / conversion operators
        for back in range(1, 5):
            if self.text(paren - back) == "operator":
                parts = [self.text(k) for k in range(paren - back, paren)]
                parts = ["operator" + "".join(parts[1:]) if len(parts) > 1 and not
                         _IDENT.fullmatch(parts[1]) else " ".join(parts)]
                q = paren - back - 1
                break
        else:
            if self.text(q) == ">":  # a template specialisation f<int>(...)
                q = self.before_angles(q)
            if not _IDENT.fullmatch(self.text(q)):
                return "?"
            parts = [self.text(q)]
            q -= 1
            if self.text(q) == "~":
                parts.insert(0, "~")
                q -= 1
        while self.text(q) == "::":
            q -= 1
            if self.text(q) == ">":  # Outer<T>::name
                q = self.before_angles(q)
            if not _IDENT.fullmatch(self.text(q)):
                break
            parts.insert(0, self.text(q) + "::")
            q -= 1
        return "".join(parts)

    def function_name(self, head):
        angles = 0  # inside template arguments: std::function<void()> f(...)
        for i in head:
            tx = self.text(i)
            if tx == "<" and _IDENT.fullmatch(self.text(i - 1)) and self.text(i - 1) != "operator":
                angles += 1
            elif tx == ">" and angles > 0:
                angles -= 1
            elif tx == "(" and angles == 0 and self.text(i - 1) not in _NOT_A_NAME_CALL:
                return self.name_before(i)
        return "?"

    def variable_name(self, head):
        for i in head:
            if self.text(i) == "=" and self.text(i - 1) != "operator":
                j = i - 1
                while j >= 0 and self.text(j) == "]" and self.m[j] >= 0:  # name[N] = ...
                    j = self.m[j] - 1
                return self.text(j) if _IDENT.fullmatch(self.text(j)) else "?"
        if head and _IDENT.fullmatch(self.text(head[-1])):
            return self.text(head[-1])
        return ""

    # --- the scan --------------------------------------------------------------------------
    def classify(self, brace, decl_start, scope_kind):
        """'namespace' | 'class' | 'data' | 'function' | 'lambda' for the `{` at `brace`."""
        idx, inside = self.top_level(decl_start, brace)
        head = self.skip_template_header(idx)
        introducer = self.lambda_at(brace, decl_start - 1)
        if introducer >= 0:
            return "lambda", (head, introducer)
        if inside or scope_kind == "data":
            return "data", head
        first = self.text(head[0]) if head else ""
        if first == "namespace" or (first == "extern" and len(head) == 2) or (
                first == "inline" and len(head) > 1 and self.text(head[1]) == "namespace"):
            return "namespace", head
        calls = [i for i in head if self.text(i) == "("]
        if first in _CLASS_KEYS and all(self.text(i - 1) in _NOT_A_NAME_CALL for i in calls):
            return ("data" if first == "enum" else "class"), head
        if any(self.text(i) == "=" and self.text(i - 1) != "operator" for i in head):
            return "data", head
        p = self.before_specifiers(brace, decl_start - 1)
        if self.text(p) == ")" and calls:
            return "function", head
        if self.text(p) == "}" and self.has_init_list(head):
            return "function", head
        return "data", head

    def has_init_list(self, head):
        seen_call = False
        for i in head:
            if self.text(i) == "(":
                seen_call = True
            elif self.text(i) == ":" and seen_call:
                return True
        return False

    def class_name(self, head):
        k = 1
        while k < len(head) and (self.text(head[k]) in ("class", "struct", "alignas") or
                                 self.text(head[k]) in ("(", "[")):
            k += 1
        name = []
        while k < len(head) and (_IDENT.fullmatch(self.text(head[k])) or
                                 self.text(head[k]) == "::"):
            if self.text(head[k]) == "final":
                break
            name.append(self.text(head[k]))
            k += 1
        return "".join(name)

    def parse(self):
        t = self.t
        # Each scope: (kind, name, index of its closing brace, declaration start to resume).
        scopes = [("namespace", "", len(t), 0)]
        decl_start = 0
        i = 0
        while i < len(t):
            kind, _, end, resume = scopes[-1]
            if i == end:
                scopes.pop()
                decl_start = resume if kind == "data" else i + 1
                i += 1
                continue
            tx = t[i].text
            if tx == ";" or (tx == "," and kind == "data"):
                decl_start = i + 1
            elif tx == ":" and self.text(i - 1) in _ACCESS:
                decl_start = i + 1
            elif tx == "{":
                what, head = self.classify(i, decl_start, kind)
                close = self.m[i] if self.m[i] >= 0 else len(t) - 1
                qual = "".join(s[1] + "::" for s in scopes if s[0] in ("class", "data") and s[1])
                if what in ("function", "lambda"):
                    start = t[decl_start].line if decl_start < i else t[i].line
                    if what == "function":
                        name = self.function_name(head)
                    else:
                        head, introducer = head
                        var = self.variable_name(head)
                        if self.text(introducer - 1) == "=" and var:
                            name = f"{var} (lambda)"  # auto name = [...](...) {...};
                        else:
                            name = "(lambda)"
                            start = t[introducer].line
                    if "::" not in name or what == "lambda":
                        name = qual + name
                    self.functions.append(Function(name, start, t[close].line, what))
                    if what == "function":  # a lambda is an expression: its statement goes on
                        decl_start = close + 1
                    i = close + 1
                    continue
                if what == "namespace":
                    scopes.append(("namespace", "", close, 0))
                elif what == "class":
                    scopes.append(("class", self.class_name(head), close, 0))
                else:
                    name = self.variable_name(head) if kind != "data" else ""
                    scopes.append(("data", name, close, decl_start))
                decl_start = i + 1
            i += 1
        # A lambda inside a function's declaration (default argument, member initialiser) is
        # part of that function.
        self.functions.sort(key=lambda f: (f.start, -f.end, f.kind != "function"))
        kept = []
        for f in self.functions:
            if kept and kept[-1].start <= f.start and f.end <= kept[-1].end:
                continue
            kept.append(f)
        self.functions = kept
        return kept


def functions_in(src):
    return Parser(src).parse()


def load_exceptions(path):
    entries = []
    with open(path) as f:
        for raw in f:
            entry = raw.split("#", 1)[0].strip()
            if entry:
                entries.append(entry)
    return entries


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--exceptions", help="file of known long functions, path:function a line")
    ap.add_argument("limit", type=int)
    ap.add_argument("files", nargs="*")
    args = ap.parse_args(argv)
    allowed = load_exceptions(args.exceptions) if args.exceptions else []
    used = set()
    failing = 0
    rows = []
    for path in args.files:
        with open(path, encoding="utf-8", errors="replace") as f:
            src = f.read()
        parser = Parser(src)
        line = parser.unbalanced()
        if line is not None:
            # Braces split by #if/#else, say: the lengths would be wrong, so no verdict.
            print(f"{path}:{line}: unbalanced bracket (preprocessor?): cannot check this file")
            failing += 1
            continue
        for fn in parser.parse():
            if fn.lines > args.limit:
                key = f"{path}:{fn.name}"
                known = key in allowed
                used.add(key) if known else None
                failing += not known
                rows.append((fn.lines, path, fn.start, fn.name, known))
    for lines, path, start, name, known in sorted(rows, reverse=True):
        print(f"{lines:5d} {path}:{start} {name}" + ("  (known exception)" if known else ""))
    for entry in allowed:
        if entry not in used:
            print(f"note: exception {entry} matches no function over {args.limit} lines; "
                  "remove it from the list")
    print(f"check-function-length: {len(args.files)} files, {failing} failing (limit "
          f"{args.limit} lines)" + (f", {len(used)} known exceptions" if used else ""))
    return 1 if failing else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

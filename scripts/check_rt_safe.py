#!/usr/bin/env python3
"""Checks the functions marked TELEOP_RT (common/core/rt_safe.hpp; docs/architecture.md §4.6).

    scripts/check_rt_safe.py FILE...

For every declaration or definition that starts with the TELEOP_RT marker:
  - it must be declared noexcept;
  - its body (written in place, or found as `Class::name(...) {` / `name(...) {` in a given
    file of the same directory) must not name a forbidden call: allocation (new, delete,
    malloc & co, make_unique, make_shared, std::function, std::string and string streams,
    a std container constructed by value, push_back/emplace/insert/resize/reserve), a lock
    (mutex, lock_guard, unique_lock, scoped_lock, condition_variable, .lock()), I/O (printf &
    co, std::cout/cerr, spdlog, fmt, sleeping) or throw;
  - a marked declaration whose body is found nowhere is an error too (so no marked function
    goes unchecked), unless it is pure virtual (= 0), defaulted or deleted.
Comments and string literals are ignored (the tokenizer of check_function_length.py). Calls to
unmarked functions are not followed: mark them too. Exit status 1 on any problem, each named
FILE:LINE: function: what.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_function_length as cfl  # noqa: E402

MARKER = "TELEOP_RT"

# Identifiers that may not appear in an RT body, with why.
FORBIDDEN_NAMES = {
    "new": "allocates (new)",
    "delete": "deallocates (delete)",
    "malloc": "allocates (malloc)",
    "calloc": "allocates (calloc)",
    "realloc": "allocates (realloc)",
    "aligned_alloc": "allocates (aligned_alloc)",
    "posix_memalign": "allocates (posix_memalign)",
    "strdup": "allocates (strdup)",
    "make_unique": "allocates (make_unique)",
    "make_shared": "allocates (make_shared)",
    "to_string": "allocates (std::to_string)",
    "ostringstream": "allocates (a string stream)",
    "stringstream": "allocates (a string stream)",
    "push_back": "may allocate (push_back)",
    "emplace_back": "may allocate (emplace_back)",
    "emplace": "may allocate (emplace)",
    "insert": "may allocate (insert)",
    "resize": "may allocate (resize)",
    "reserve": "allocates (reserve)",
    "throw": "throws",
    "mutex": "takes a lock (mutex)",
    "lock_guard": "takes a lock (lock_guard)",
    "unique_lock": "takes a lock (unique_lock)",
    "scoped_lock": "takes a lock (scoped_lock)",
    "shared_lock": "takes a lock (shared_lock)",
    "condition_variable": "blocks (condition_variable)",
    "pthread_mutex_lock": "takes a lock (pthread_mutex_lock)",
    "printf": "does I/O (printf)",
    "fprintf": "does I/O (fprintf)",
    "puts": "does I/O (puts)",
    "cout": "does I/O (std::cout)",
    "cerr": "does I/O (std::cerr)",
    "clog": "does I/O (std::clog)",
    "spdlog": "logs (spdlog)",
    "fmt": "formats, allocating (fmt)",
    "sleep_for": "sleeps",
    "sleep_until": "sleeps",
    "usleep": "sleeps",
    "nanosleep": "sleeps",
}
# std:: names that allocate when constructed by value (a reference or pointer to one is fine).
ALLOCATING_TYPES = {"string", "vector", "map", "unordered_map", "set", "unordered_set", "deque",
                    "list", "function", "any"}
SPECIFIERS = {"const", "volatile", "noexcept", "override", "final", "&", "&&", "mutable",
              "constexpr"}


class Source:
    def __init__(self, path, text):
        self.path = path
        self.t = cfl.tokenize(text)
        self.m = cfl.match_brackets(self.t)

    def text(self, i):
        return self.t[i].text if 0 <= i < len(self.t) else ""


def class_scopes(src):
    """{index of '{': class name} for every class or struct body in src."""
    out = {}
    for i, tok in enumerate(src.t):
        if tok.text != "{":
            continue
        j = i - 1
        name = None
        while j >= 0 and src.text(j) not in (";", "{", "}"):
            if src.text(j) == ")" and src.m[j] >= 0:
                break  # a function or control statement, not a class head
            if src.text(j) in ("class", "struct") and src.text(j - 1) != "enum":
                name = src.text(j + 1)
            j -= 1
        if name is not None:
            out[i] = name
    return out


def enclosing_class(src, index, scopes):
    """Name of the innermost class whose body holds token `index` (None: none)."""
    best = None
    for open_i, name in scopes.items():
        close = src.m[open_i]
        if open_i < index < close and (best is None or open_i > best[0]):
            best = (open_i, name)
    return best[1] if best else None


def declaration_end(src, start):
    """Index of the `;` or `{` that ends the declaration starting at `start`, and whether the
    `{` opens the body (not a braced default argument or initialiser)."""
    i = start
    while i < len(src.t):
        tx = src.text(i)
        if tx in ("(", "[") and src.m[i] > i:
            i = src.m[i] + 1
            continue
        if tx == ";":
            return i
        if tx == "{":
            return i
        i += 1
    return len(src.t) - 1


def signature(src, start, end):
    """(name, qualifier, index of the parameter list's ')') of the declaration in [start, end)."""
    i = start
    while i < end:
        if src.text(i) == "(" and src.text(i - 1) not in cfl._NOT_A_NAME_CALL and \
                src.text(i - 1) not in ("[[", "]", "alignas"):
            prev = src.text(i - 1)
            if prev == "]":  # attribute list [[...]] then a name? skip
                i += 1
                continue
            qual = src.text(i - 3) if src.text(i - 2) == "::" else None
            return prev, qual, src.m[i]
        if src.text(i) in ("(", "[") and src.m[i] > i:
            i = src.m[i] + 1
            continue
        i += 1
    return None, None, None


def body_problems(src, open_i):
    """[(line, why)] for the forbidden names in the body that opens at `open_i`."""
    close = src.m[open_i]
    out = []
    i = open_i + 1
    while i < close:
        tx = src.text(i)
        if tx in FORBIDDEN_NAMES:
            # `x.insert(` etc. are calls; a bare identifier named like one (e.g. a variable
            # `reserve`) is rare enough to rename. `lock` alone is allowed (atomics have none).
            out.append((src.t[i].line, FORBIDDEN_NAMES[tx]))
        elif tx == "lock" and src.text(i - 1) in (".", "->") and src.text(i + 1) == "(":
            out.append((src.t[i].line, "takes a lock (.lock())"))
        elif tx == "std" and src.text(i + 1) == "::" and src.text(i + 2) in ALLOCATING_TYPES:
            j = i + 3
            if src.text(j) == "<":  # skip the template arguments
                depth = 0
                while j < close:
                    if src.text(j) == "<":
                        depth += 1
                    elif src.text(j) == ">":
                        depth -= 1
                        if depth == 0:
                            break
                    elif src.text(j) == ">>":
                        depth -= 2
                        if depth <= 0:
                            break
                    j += 1
            if src.text(j + 1) not in ("&", "&&", "*"):
                out.append((src.t[i].line, f"allocates (std::{src.text(i + 2)} by value)"))
        i += 1
    return out


def definitions(src, name, qual):
    """Indices of '{' opening the body of `qual::name(...)` (or free `name(...)`) in src."""
    out = []
    for i, tok in enumerate(src.t):
        if tok.text != name or src.text(i + 1) != "(":
            continue
        if qual is not None:
            if src.text(i - 1) != "::" or src.text(i - 2) != qual:
                continue
        elif src.text(i - 1) in (".", "->", "::"):
            continue
        close = src.m[i + 1]
        if close < 0:
            continue
        j = close + 1
        while src.text(j) in SPECIFIERS or (src.text(j) == "noexcept" and src.text(j + 1) == "("):
            j += 1
        if src.text(j) == "->":  # trailing return type
            while j < len(src.t) and src.text(j) not in ("{", ";"):
                j += 1
        if src.text(j) == "{":
            out.append(j)
    return out


def check(paths):
    sources = {}
    for p in paths:
        with open(p, encoding="utf-8") as f:
            sources[p] = Source(p, f.read())
    problems = []
    marked = 0
    for path, src in sources.items():
        scopes = class_scopes(src)
        for i, tok in enumerate(src.t):
            if tok.text != MARKER:
                continue
            end = declaration_end(src, i + 1)
            name, qual, close = signature(src, i + 1, end)
            where = f"{path}:{tok.line}"
            if name is None:
                problems.append(f"{where}: {MARKER} marks no function")
                continue
            marked += 1
            cls = qual or enclosing_class(src, i, scopes)
            label = f"{cls}::{name}" if cls else name
            tail = [src.text(k) for k in range(close + 1, end)]
            if "noexcept" not in tail:
                problems.append(f"{where}: {label}: an RT function must be noexcept")
            if src.text(end) == "{":
                bodies = [(src, end)]
            elif tail[-2:] == ["=", "NUM"] or tail[-2:] in (["=", "default"], ["=", "delete"]):
                continue  # pure virtual (= 0), defaulted or deleted: no body of its own
            else:
                directory = os.path.dirname(path)
                bodies = [(s, b) for p2, s in sources.items() if os.path.dirname(p2) == directory
                          for b in definitions(s, name, cls)]
                if not bodies:
                    problems.append(f"{where}: {label}: no definition found in "
                                    f"{directory or '.'} to check")
            for s, b in bodies:
                for line, why in body_problems(s, b):
                    problems.append(f"{s.path}:{line}: {label}: {why}")
    return marked, sorted(set(problems))


def main(argv):
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    marked, problems = check(argv)
    for p in problems:
        print(p)
    if problems:
        print(f"check-rt: {len(problems)} problem(s) in {marked} RT function(s)")
        return 1
    print(f"check-rt: {marked} RT function(s), each noexcept with no forbidden call")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env bash
# Fails if a function marked TELEOP_RT (common/core/rt_safe.hpp) is not noexcept or names a
# forbidden call (allocation, lock, I/O, throw) in its body (docs/architecture.md §4.6): the
# checker's own hand-made snippets first, then the tree.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 tests/scripts/test_check_rt_safe.py
python3 scripts/check_rt_safe.py $(git ls-files 'common/*.cpp' 'common/*.hpp' | grep -v '^common/core/rt_safe.hpp$')

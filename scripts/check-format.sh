#!/usr/bin/env bash
# Fails if any C++ source differs from clang-format's output (.clang-format: Google, 100 cols).
set -euo pipefail
cd "$(dirname "$0")/.."
files=$(git ls-files '*.cpp' '*.hpp' '*.h' '*.cc')
clang-format --dry-run --Werror $files
echo "check-format: $(echo "$files" | wc -l) files formatted"

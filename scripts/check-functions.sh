#!/usr/bin/env bash
# Fails if a function in common/ or supervisor/ is over 120 lines, or a product file over 800
# (issue 16): the function checker's own hand-made snippets first, then the tree.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 tests/scripts/test_check_function_length.py
python3 scripts/check_function_length.py --exceptions scripts/function_length_exceptions.txt 120 \
  $(git ls-files 'common/*.cpp' 'common/*.hpp' 'supervisor/*.cpp' 'supervisor/*.hpp')
# And no product source file over 800 lines.
long=$(git ls-files 'common/*.cpp' 'common/*.hpp' 'supervisor/*.cpp' 'supervisor/*.hpp' \
  'master_node/*.cpp' 'slave_node/*.cpp' | xargs wc -l | awk '$2 != "total" && $1 > 800')
if [ -n "$long" ]; then
  echo "check-functions: product files over 800 lines:"
  echo "$long"
  exit 1
fi
echo "check-functions: no product file over 800 lines"

#!/usr/bin/env bash
# Writes the man page of one teleop program from its own --help and --version (help2man):
#   scripts/make-man.sh PROGRAM OUTPUT.1 "one-line description"
# For teleopctl, each command's --help becomes a subsection of COMMANDS.
set -euo pipefail
prog=$1
out=$2
name=$3
include=$(mktemp)
trap 'rm -f "$include"' EXIT
if [ "$(basename "$prog")" = teleopctl ]; then
  {
    echo "[COMMANDS]"
    for cmd in analyze simulate launch node keygen set identify replay estop status console relay bridge; do
      echo ".SS $cmd"
      echo ".nf"
      # roff: a line starting with . or ' is a request; a backslash is an escape.
      "$prog" "$cmd" --help | sed -e 's/\\/\\e/g' -e "s/^[.']/\\\\\\&&/"
      echo ".fi"
    done
    echo "[SEE ALSO]"
    echo "teleop-master(1), teleop-slave(1), teleop-supervisor(1); /usr/share/doc/teleop/docs/"
  } >"$include"
else
  {
    echo "[SEE ALSO]"
    echo "teleopctl(1); /usr/share/doc/teleop/docs/"
  } >"$include"
fi
help2man --no-info --no-discard-stderr --section=1 --name="$name" --include="$include" \
  --output="$out" "$prog"

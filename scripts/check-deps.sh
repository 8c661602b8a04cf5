#!/usr/bin/env bash
# Fails if a product source includes a directory that is not below its own in the layer table
# (docs/architecture.md §3.1), or if a library that must stay free of protobuf includes it
# (§3.2). Scans every `#include "..."` (and `#include <...>` naming a project directory) in
# common/, supervisor/, master_node/, slave_node/ and python/; proto/ is generated, and its headers
# (teleop/v1/*.pb.h) count as the bottom layer. Needs python3 only, which Debian installs with
# clang-format (check-format.sh).
#
#   scripts/check-deps.sh            check the tree this script sits in
#   scripts/check-deps.sh --root DIR check another copy of it
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
if [[ "${1:-}" == "--root" && -n "${2:-}" ]]; then
  root="$(cd "$2" && pwd)"
elif [[ $# -gt 0 ]]; then
  echo "usage: $0 [--root DIR]" >&2
  exit 2
fi

exec python3 - "$root" <<'PY'
import os
import re
import sys

root = sys.argv[1]

# The layers, bottom to top (docs/architecture.md §3.1). A directory may include its own files
# and those of any directory in a LOWER layer; never one in its own layer or above.
LAYERS = [
    ["proto", "common/core"],
    ["common/control", "common/stability", "common/rt", "common/transport", "common/record",
     "common/bridge", "common/kinematics"],
    ["common/sim"],
    ["common/device"],
    ["common/scene", "common/node"],
    ["common/config", "common/telemetry"],
    ["common/runtime", "common/session"],
    ["supervisor/core"],
    ["supervisor/daemon", "supervisor/teleopctl", "master_node", "slave_node"],
    ["python"],
]
# The real-time side and the plain-data libraries see no protobuf (docs/architecture.md §3.2).
NO_PROTOBUF = ["common/core", "common/control", "common/stability", "common/sim",
               "common/device", "common/rt", "common/scene", "common/node", "common/bridge",
               "common/kinematics"]

SCANNED = ["common", "supervisor", "master_node", "slave_node", "python"]
# Top-level directories of the repository that are not product code: never included by it.
NOT_PRODUCT = ["tests", "bench", "fuzz", "scripts", "examples", "deploy", "docs", "cmake"]
SOURCE = (".cpp", ".hpp", ".h", ".cc", ".hh", ".cxx", ".ipp", ".inc")

layer_of = {d: i for i, names in enumerate(LAYERS) for d in names}
INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]')


def directory_of(path):
    """The layer-table directory a repository path belongs to, or None."""
    parts = path.split("/")
    if parts[0] in ("teleop", "foxglove"):  # generated from proto/teleop/..., proto/foxglove/...
        return "proto"
    if parts[0] in ("common", "supervisor") and len(parts) > 2:
        return parts[0] + "/" + parts[1]
    if parts[0] in ("master_node", "slave_node", "proto", "python") and len(parts) > 1:
        return parts[0]
    return None


problems = []
files = includes = 0
for top in SCANNED:
    for dirpath, dirnames, filenames in os.walk(os.path.join(root, top)):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("build"))
        for name in sorted(filenames):
            if not name.endswith(SOURCE):
                continue
            full = os.path.join(dirpath, name)
            rel = os.path.relpath(full, root).replace(os.sep, "/")
            src = directory_of(rel)
            if src not in layer_of:
                problems.append(f"{rel}: its directory is not in the layer table of "
                                f"scripts/check-deps.sh (add it, and to docs/architecture.md §3.1)")
                continue
            files += 1
            with open(full, encoding="utf-8", errors="replace") as f:
                for number, line in enumerate(f, 1):
                    m = INCLUDE.match(line)
                    if not m:
                        continue
                    bracket, target = m.groups()
                    first = target.split("/")[0]
                    if first == "google" and target.startswith("google/protobuf/"):
                        if src in NO_PROTOBUF:
                            problems.append(f"{rel}:{number}: {line.strip()}: {src} must not "
                                            f"use protobuf (docs/architecture.md §3.2)")
                        continue
                    if first in NOT_PRODUCT:
                        problems.append(f"{rel}:{number}: {line.strip()}: product code never "
                                        f"includes {first}/")
                        continue
                    dst = directory_of(target)
                    if dst is None:
                        if bracket == '"' and "/" not in target:
                            problems.append(f"{rel}:{number}: {line.strip()}: project headers "
                                            f"are included by their path from the repository "
                                            f"root")
                        continue  # a system or third-party header
                    includes += 1
                    if dst not in layer_of:
                        problems.append(f"{rel}:{number}: {line.strip()}: {dst} is not in the "
                                        f"layer table of scripts/check-deps.sh")
                        continue
                    if dst == "proto" and src in NO_PROTOBUF:
                        problems.append(f"{rel}:{number}: {line.strip()}: {src} must not "
                                        f"use protobuf (docs/architecture.md §3.2)")
                        continue
                    if dst == src:
                        continue
                    if layer_of[dst] >= layer_of[src]:
                        where = "the same layer as" if layer_of[dst] == layer_of[src] else "above"
                        problems.append(
                            f"{rel}:{number}: {line.strip()}: {src} (layer {layer_of[src]}) "
                            f"includes {dst} (layer {layer_of[dst]}), {where} it; only lower "
                            f"layers may be included (docs/architecture.md §3.1)")

for p in problems:
    print(p)
if problems:
    print(f"check-deps: {len(problems)} problem(s) in {files} files", file=sys.stderr)
    sys.exit(1)
print(f"check-deps: {files} files, {includes} project includes, layers respected")
PY

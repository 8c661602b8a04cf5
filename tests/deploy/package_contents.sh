#!/usr/bin/env bash
# deploy.package_contents: builds the Debian package from BUILD_DIR's binaries (cpack with the
# build's CPackConfig.cmake: no second compilation; scripts/package.sh makes the Release one)
# and checks what is in it: the four executables, the three units, the examples, the docs, the
# sysusers/tmpfiles/udev files, the .proto files and their descriptor set, the Python module
# (when built), Depends from dpkg-shlibdeps, the maintainer scripts; then extracts it and runs
# the extracted teleopctl (no LD_LIBRARY_PATH) on the extracted example, and imports the
# extracted module into /usr/bin/python3.
#
#   package_contents.sh BUILD_DIR SOURCE_DIR
# Exit 0 pass, 1 fail, 77 skipped (no dpkg-deb/dpkg-shlibdeps).
set -euo pipefail

build=$(cd "${1:?usage: package_contents.sh BUILD_DIR SOURCE_DIR}" && pwd)
src=$(cd "${2:?usage: package_contents.sh BUILD_DIR SOURCE_DIR}" && pwd)

for tool in cpack dpkg-deb dpkg-shlibdeps; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    echo "SKIP: $tool not found (apt-get install dpkg-dev cmake)"
    exit 77
  fi
done
[ -f "$build/CPackConfig.cmake" ] || { echo "FAIL: no $build/CPackConfig.cmake"; exit 1; }

tmp=$(mktemp -d "${TMPDIR:-/tmp}/teleop-deploy-package.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
failures=0
fail() {
  echo "FAIL: $*"
  failures=$((failures + 1))
}

# -B: the package and CPack's staging tree in tmp (not in the build directory).
start=$(date +%s)
if ! cpack --config "$build/CPackConfig.cmake" -G DEB -B "$tmp/out" >"$tmp/cpack.log" 2>&1; then
  cat "$tmp/cpack.log"
  echo "FAIL: cpack"
  exit 1
fi
shopt -s nullglob
debs=("$tmp"/out/teleop_*.deb)
if [ "${#debs[@]}" -ne 1 ]; then
  cat "$tmp/cpack.log"
  echo "FAIL: expected one teleop_*.deb, got: ${debs[*]:-none}"
  exit 1
fi
deb=${debs[0]}
echo "cpack: $(basename "$deb"), $(du -h "$deb" | cut -f1), $(($(date +%s) - start)) s"

# Contents.
dpkg-deb -c "$deb" | awk '{ print $6 }' | sed -e 's|^\./|/|' -e 's| ->.*||' >"$tmp/contents"
for f in /usr/bin/teleop-master /usr/bin/teleop-slave /usr/bin/teleop-supervisor /usr/bin/teleopctl \
         /usr/lib/systemd/system/teleop-master.service \
         /usr/lib/systemd/system/teleop-slave.service \
         /usr/lib/systemd/system/teleop-supervisor.service \
         /usr/lib/sysusers.d/teleop.conf /usr/lib/tmpfiles.d/teleop.conf \
         /usr/lib/udev/rules.d/70-teleop.rules \
         /usr/share/teleop/examples/live.textproto /usr/share/doc/teleop/README.md; do
  grep -qxF "$f" "$tmp/contents" || fail "$f not in the package"
done
# The schemas for any language: every .proto of proto/ and their FileDescriptorSet.
while IFS= read -r f; do
  grep -qxF "/usr/share/teleop/proto/$f" "$tmp/contents" || fail "proto/$f not in the package"
done < <(cd "$src/proto" && find . -type f -name '*.proto' | sed 's|^\./||')
grep -qxF /usr/share/teleop/proto/teleop.desc "$tmp/contents" || fail "teleop.desc not in the package"
# The Python module, when this build made it (docs/python.md).
python_module=$(grep -q '^TELEOP_BUILD_PYTHON:BOOL=ON$' "$build/CMakeCache.txt" && echo yes || true)
if [ -n "$python_module" ]; then
  grep -Eqx '/usr/lib/python3/dist-packages/teleop\.cpython-[^/]*\.so' "$tmp/contents" ||
    fail "the Python module teleop is not in /usr/lib/python3/dist-packages"
fi
# Every file of examples/ (scenes too).
while IFS= read -r f; do
  grep -qxF "/usr/share/teleop/examples/$f" "$tmp/contents" || fail "examples/$f not in the package"
done < <(cd "$src/examples" && find . -type f | sed 's|^\./||')
# Every page of docs/, beside the README that links to them.
while IFS= read -r f; do
  grep -qxF "/usr/share/doc/teleop/docs/$f" "$tmp/contents" || fail "docs/$f not in the package"
done < <(cd "$src/docs" && find . -type f -name '*.md' | sed 's|^\./||')
# Nothing in /etc (no conffiles: the administrator writes /etc/teleop/*.textproto).
if grep -q '^/etc/' "$tmp/contents"; then
  fail "the package installs into /etc: $(grep '^/etc/' "$tmp/contents" | tr '\n' ' ')"
fi
echo "contents: $(grep -vc '/$' "$tmp/contents") files"

# Control fields.
field() { dpkg-deb -f "$deb" "$1"; }
version=$(sed -n 's/^set(CPACK_PACKAGE_VERSION "\(.*\)")$/\1/p' "$build/CPackConfig.cmake")
[ "$(field Package)" = teleop ] || fail "Package: '$(field Package)', expected teleop"
if [ -z "$version" ] || [ "$(field Version)" != "$version" ]; then
  fail "Version: '$(field Version)', expected '$version' (project())"
fi
[ -n "$(field Maintainer)" ] || fail "no Maintainer"
[ -n "$(field Section)" ] || fail "no Section"
[ -n "$(field Description)" ] || fail "no Description"
depends=$(field Depends)
echo "Depends: $depends"
for lib in libzmq5 libprotobuf; do
  grep -Eq "(^|, )${lib}" <<<"$depends" || fail "Depends does not name $lib"
done

# Maintainer scripts: postinst creates the user and reloads systemd only under systemd; no
# unit is enabled or started.
dpkg-deb -e "$deb" "$tmp/control"
for s in postinst prerm postrm; do
  if [ ! -x "$tmp/control/$s" ]; then
    fail "no executable $s"
  elif ! sh -n "$tmp/control/$s"; then
    fail "$s: shell syntax error"
  fi
done
if [ -f "$tmp/control/postinst" ]; then
  grep -q 'systemd-sysusers' "$tmp/control/postinst" || fail "postinst does not run systemd-sysusers"
  grep -q 'useradd' "$tmp/control/postinst" || fail "postinst has no useradd fallback"
  grep -q '/run/systemd/system' "$tmp/control/postinst" || fail "postinst does not check for systemd"
  if grep -Eq 'systemctl[^#]*(enable|start|restart)' "$tmp/control/postinst"; then
    fail "postinst enables or starts units"
  fi
fi

# postinst run against stub commands (nothing on this machine changes): with systemd-sysusers,
# it applies teleop.conf; without, useradd creates the system user. systemd is not PID 1 here,
# so systemctl must not be called.
postinst_run() {  # SCENARIO: with-sysusers | without-sysusers
  local stubs=$tmp/stubs-$1 c
  mkdir -p "$stubs"
  for c in systemd-sysusers systemd-tmpfiles useradd install udevadm systemctl getent; do
    [ "$1" = without-sysusers ] && [ "$c" = systemd-sysusers ] && continue
    printf '#!/bin/sh\necho "%s $*" >>"%s/calls"\n%s\n' "$c" "$stubs" \
      "$([ "$c" = getent ] && echo 'exit 2' || echo 'exit 0')" >"$stubs/$c"
    chmod +x "$stubs/$c"
  done
  : >"$stubs/calls"
  PATH=$stubs /bin/sh "$tmp/control/postinst" configure >"$stubs/out" 2>&1 ||
    { cat "$stubs/out"; fail "postinst ($1) failed"; }
}
if [ -f "$tmp/control/postinst" ]; then
  postinst_run with-sysusers
  grep -qx 'systemd-sysusers teleop.conf' "$tmp/stubs-with-sysusers/calls" ||
    fail "postinst did not run 'systemd-sysusers teleop.conf': $(cat "$tmp/stubs-with-sysusers/calls")"
  postinst_run without-sysusers
  grep -q '^useradd .*--system.* teleop$' "$tmp/stubs-without-sysusers/calls" ||
    fail "postinst without systemd-sysusers did not useradd teleop: $(cat "$tmp/stubs-without-sysusers/calls")"
  if [ ! -d /run/systemd/system ] && grep -qh '^systemctl' "$tmp"/stubs-*/calls; then
    fail "postinst called systemctl although systemd is not PID 1"
  fi
fi

# Extracted, the executables run on the system's libraries alone.
dpkg-deb -x "$deb" "$tmp/x"
for b in teleop-master teleop-slave teleop-supervisor teleopctl; do
  if readelf -d "$tmp/x/usr/bin/$b" | grep -Eq '\((RPATH|RUNPATH)\)'; then
    fail "$b has an RPATH/RUNPATH: $(readelf -d "$tmp/x/usr/bin/$b" | grep -E 'R(UN)?PATH')"
  fi
done
for b in teleop-master teleop-slave teleop-supervisor; do
  env -u LD_LIBRARY_PATH "$tmp/x/usr/bin/$b" --help >"$tmp/help.out" 2>&1 ||
    { cat "$tmp/help.out"; fail "extracted $b --help failed"; }
done
example=$tmp/x/usr/share/teleop/examples/live.textproto
rc=0
env -u LD_LIBRARY_PATH "$tmp/x/usr/bin/teleopctl" analyze "$example" >"$tmp/analyze.out" 2>&1 || rc=$?
head -n 3 "$tmp/analyze.out"
if [ "$rc" -ne 0 ]; then
  fail "extracted teleopctl analyze live.textproto: exit $rc"
elif ! head -n 1 "$tmp/analyze.out" | grep -Eq ': (stable|unstable|uncertain)$'; then
  fail "extracted teleopctl analyze printed no verdict"
fi

# The extracted module imports into Debian's python3 and names the package's version.
if [ -n "$python_module" ] && [ -x /usr/bin/python3 ]; then
  got=$(env PYTHONPATH="$tmp/x/usr/lib/python3/dist-packages" /usr/bin/python3 -c \
    'import teleop; print(teleop.__version__)' 2>&1) || true
  [ "$got" = "$version" ] || fail "extracted Python module: '$got', expected version '$version'"
fi

if [ "$failures" -ne 0 ]; then
  echo "FAILED: $failures check(s)"
  exit 1
fi
echo "PASSED"

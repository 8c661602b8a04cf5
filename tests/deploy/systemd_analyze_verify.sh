#!/usr/bin/env bash
# deploy.systemd_analyze_verify: installs the project into a temporary root (DESTDIR, prefix
# /usr) and checks the installed systemd units with `systemd-analyze verify --root=ROOT`, which
# resolves ExecStart= inside ROOT (systemd 252; systemd need not be PID 1). The host's own
# units are copied into ROOT first, for the targets ours depend on (sysinit.target, ...).
# Negative controls (a misspelt key, a missing ExecStart binary) must make verify fail, or
# this test could not. Also applies sysusers.d and tmpfiles.d to ROOT.
#
#   systemd_analyze_verify.sh BUILD_DIR
# Exit 0 pass, 1 fail, 77 skipped (no systemd-analyze).
set -euo pipefail

build=${1:?usage: systemd_analyze_verify.sh BUILD_DIR}
units=(teleop-master.service teleop-slave.service teleop-supervisor.service)

if ! command -v systemd-analyze >/dev/null 2>&1; then
  echo "SKIP: systemd-analyze not found (apt-get install systemd)"
  exit 77
fi
systemd-analyze --version | head -n 1

tmp=$(mktemp -d "${TMPDIR:-/tmp}/teleop-deploy-verify.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
root=$tmp/root
failures=0
fail() {
  echo "FAIL: $*"
  failures=$((failures + 1))
}

# The host's units (the targets ours are ordered after and wanted by), then the project.
host_units=
for d in /usr/lib/systemd/system /lib/systemd/system; do
  if [ -f "$d/sysinit.target" ]; then host_units=$d; break; fi
done
[ -n "$host_units" ] || { echo "FAIL: no sysinit.target on this host"; exit 1; }
mkdir -p "$root/usr/lib/systemd/system"
cp -a "$host_units/." "$root/usr/lib/systemd/system/"
# Our units must come from the install, not from the host (were the package installed here).
rm -f "${units[@]/#/$root/usr/lib/systemd/system/}"
DESTDIR=$root cmake --install "$build" --prefix /usr >"$tmp/install.log" 2>&1 || {
  cat "$tmp/install.log"
  echo "FAIL: cmake --install"
  exit 1
}
unitdir=$root/usr/lib/systemd/system
for u in "${units[@]}"; do
  [ -f "$unitdir/$u" ] || fail "$u not installed in /usr/lib/systemd/system"
done
for b in teleop-master teleop-slave teleop-supervisor teleopctl; do
  [ -x "$root/usr/bin/$b" ] || fail "/usr/bin/$b not installed"
done
[ "$failures" -eq 0 ] || exit 1

# verify UNIT...: passes when it exits 0 and prints nothing. --recursive-errors=no: non-zero on
# any warning about the named units (not about the host's units they pull in).
verify() {
  local out rc=0
  out=$(systemd-analyze verify --recursive-errors=no --man=no --root="$root" "$@" 2>&1) || rc=$?
  [ -z "$out" ] || printf '%s\n' "$out" >"$tmp/verify.out"
  [ -n "$out" ] || : >"$tmp/verify.out"
  [ "$rc" -eq 0 ] && [ -z "$out" ]
}

echo "--- systemd-analyze verify --root=ROOT ${units[*]}"
if verify "${units[@]}"; then
  echo "ok: the three units verify (ExecStart binaries found in ROOT/usr/bin)"
else
  cat "$tmp/verify.out"
  fail "systemd-analyze verify reported problems with the installed units"
fi

# Negative controls: each must fail verify, with the expected message.
negative() {  # NAME SED-EXPRESSION EXPECTED-OUTPUT-REGEX
  local name=$1 expr=$2 expect=$3
  sed -e "$expr" "$unitdir/teleop-master.service" >"$unitdir/$name.service"
  if cmp -s "$unitdir/teleop-master.service" "$unitdir/$name.service"; then
    fail "negative control $name: the edit '$expr' changed nothing"
  elif verify "$name.service"; then
    fail "negative control $name: systemd-analyze verify accepted it"
  elif ! grep -Eq "$expect" "$tmp/verify.out"; then
    cat "$tmp/verify.out"
    fail "negative control $name: verify failed without /$expect/"
  else
    echo "ok: negative control $name rejected: $(head -n 1 "$tmp/verify.out")"
  fi
  rm -f "$unitdir/$name.service"
}
negative teleop-misspelt 's/^Restart=on-failure/Restrat=on-failure/' "Unknown key.*Restrat"
negative teleop-nobinary 's|^ExecStart=/usr/bin/teleop-master|ExecStart=/usr/bin/teleop-nosuch|' \
  "teleop-nosuch.*not executable"

# What the brief of issue 8 fixes in the units (verify checks syntax, not these choices).
has() {  # UNIT LINE-REGEX
  grep -Eq "^$2\$" "$unitdir/$1" || fail "$1: no line matching '^$2\$'"
}
for u in "${units[@]}"; do
  has "$u" 'Type=notify'
  has "$u" 'NotifyAccess=main'
  has "$u" 'Restart=on-failure'
  has "$u" 'RestartSec=1s'
  has "$u" 'StartLimitIntervalSec=60'
  has "$u" 'StartLimitBurst=5'
  has "$u" 'User=teleop'
  has "$u" 'NoNewPrivileges=yes'
  has "$u" 'ProtectSystem=strict'
  has "$u" 'ProtectHome=yes'
  has "$u" 'PrivateTmp=yes'
  has "$u" 'ConfigurationDirectory=teleop'
  has "$u" 'After=network-online.target'
  has "$u" 'Wants=network-online.target'
  # The nodes set their threads' priorities themselves.
  if grep -Eq '^CPUScheduling(Policy|Priority)=' "$unitdir/$u"; then
    fail "$u sets CPUSchedulingPolicy/Priority"
  fi
done
for n in master slave; do
  u=teleop-$n.service
  has "$u" 'WatchdogSec=2s'
  has "$u" "ExecStart=/usr/bin/teleop-$n /etc/teleop/$n.textproto"
  has "$u" 'LimitRTPRIO=95'
  has "$u" 'LimitMEMLOCK=infinity'
  has "$u" 'AmbientCapabilities=CAP_SYS_NICE CAP_IPC_LOCK'
  has "$u" 'CapabilityBoundingSet=CAP_SYS_NICE CAP_IPC_LOCK'
  if grep -Eq '^(RestrictRealtime=yes|PrivateDevices=yes)' "$unitdir/$u"; then
    fail "$u: RestrictRealtime=/PrivateDevices= would break the node"
  fi
done
has teleop-supervisor.service 'WatchdogSec=5s'
has teleop-supervisor.service \
  'ExecStart=/usr/bin/teleop-supervisor /etc/teleop/supervisor.textproto --record-dir /var/lib/teleop/sessions'
has teleop-supervisor.service 'StateDirectory=teleop'

# sysusers.d and tmpfiles.d applied to ROOT: the teleop user, then its state directory.
if command -v systemd-sysusers >/dev/null 2>&1 && command -v systemd-tmpfiles >/dev/null 2>&1; then
  mkdir -p "$root/etc"
  if systemd-sysusers --root="$root" teleop.conf >"$tmp/sysusers.log" 2>&1 &&
     uid=$(awk -F: '$1 == "teleop" { print $3 }' "$root/etc/passwd") && [ -n "$uid" ]; then
    echo "ok: systemd-sysusers --root creates user teleop (uid $uid)"
    if systemd-tmpfiles --root="$root" --create teleop.conf >"$tmp/tmpfiles.log" 2>&1 &&
       [ "$(stat -c '%u %a' "$root/var/lib/teleop/sessions")" = "$uid 750" ]; then
      echo "ok: systemd-tmpfiles --root creates /var/lib/teleop/sessions (teleop, 0750)"
    else
      cat "$tmp/tmpfiles.log"
      ls -ln "$root/var/lib/teleop" 2>&1 || true
      fail "tmpfiles.d/teleop.conf did not create /var/lib/teleop/sessions owned by teleop, 0750"
    fi
  else
    cat "$tmp/sysusers.log"
    fail "sysusers.d/teleop.conf did not create user teleop"
  fi
else
  echo "note: systemd-sysusers/systemd-tmpfiles absent: sysusers.d/tmpfiles.d not applied"
fi

# Not pass/fail: how exposed the units are (systemd-analyze security, offline).
for u in "${units[@]}"; do
  systemd-analyze security --offline=yes --root="$root" "$u" 2>/dev/null | tail -n 1 || true
done

if [ "$failures" -ne 0 ]; then
  echo "FAILED: $failures check(s)"
  exit 1
fi
echo "PASSED"

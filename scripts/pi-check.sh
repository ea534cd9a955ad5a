#!/bin/sh
# `make pi-check`: install moi on the Raspberry Pi's architecture and check it computes what x86 computes.
#
# Builds a Debian arm64 root with Debian's debootstrap, runs it under qemu-user-static (binfmt_misc),
# installs moi there exactly as systemd/README.md tells a user (git clone to /opt/moi, a venv,
# `pip install '/opt/moi[pi]'`: aarch64 wheels from the package index), then
#   1. `moi identify` a real recorded trace of data/ on arm64 and on this machine: J must agree to
#      within 1e-9 relative;
#   2. `moi simulate --seed` a noisy swing on both and `moi identify` each: the same trace, the same J;
#   3. one `moi measure --sim` on arm64: a push-button measurement on the simulated rig (pymodbus RTU
#      encoder on loopback, mock GPIO) that must end in a result whose J is within 1e-5 of the truth. Its
#      trace is sampled in wall-clock time, which emulation slows, so this one is checked against the
#      truth, not digit for digit.
# Any dependency that pip had to build from source (no aarch64 wheel) is listed.
#
# Needs root (debootstrap, chroot, binfmt_misc). Slow: everything on arm64 runs emulated (~15-30 min
# the first time; the root is kept in $PI_CHECK_DIR and reused). Not part of `make test`.
#
# Environment: PI_SUITE (Debian release, default bookworm: what Raspberry Pi OS 12 is built on),
# PI_MIRROR (Debian mirror), PI_CHECK_DIR (work folder, default build/pi-check).
set -eu

SUITE=${PI_SUITE:-bookworm}
MIRROR=${PI_MIRROR:-http://deb.debian.org/debian}
REPO=$(cd "$(dirname "$0")/.." && pwd)
WORK=${PI_CHECK_DIR:-$REPO/build/pi-check}
ROOT=$WORK/root-$SUITE
OUT=$WORK/out
HOST_MOI=${HOST_MOI:-$REPO/.venv/bin/moi}
TRACE=data/cart_pendulum_20deg.csv   # a recorded trace whose rig gives J (mass and pivot distance known)
TRACE_RIG=examples/cart_pendulum.toml
SIM_RIG=examples/torsion_rig.toml

say() { printf 'pi-check: %s\n' "$*"; }
die() { printf 'pi-check: FAILED: %s\n' "$*" >&2; exit 1; }

[ "$(id -u)" = 0 ] || die "needs root (debootstrap, chroot, binfmt_misc)"
[ -x "$HOST_MOI" ] || die "no moi at $HOST_MOI on this machine (run make install)"

# --- tools: Debian's debootstrap and qemu-user-static, and the aarch64 interpreter registered -----------
if ! command -v debootstrap >/dev/null 2>&1 || ! command -v qemu-aarch64-static >/dev/null 2>&1; then
    say "installing debootstrap, qemu-user-static, binfmt-support"
    apt-get install -y -qq debootstrap qemu-user-static binfmt-support >/dev/null 2>&1 ||
        { apt-get update -qq >/dev/null && apt-get install -y -qq debootstrap qemu-user-static binfmt-support >/dev/null; }
fi
[ -e /proc/sys/fs/binfmt_misc/register ] || mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
[ -e /proc/sys/fs/binfmt_misc/qemu-aarch64 ] || update-binfmts --enable qemu-aarch64
grep -q enabled /proc/sys/fs/binfmt_misc/qemu-aarch64 || die "the qemu-aarch64 binfmt handler is not enabled"

# --- the arm64 root --------------------------------------------------------------------------------------
mkdir -p "$WORK" "$OUT"
if [ ! -f "$ROOT/.pi-check-root" ]; then
    say "debootstrap $SUITE arm64 into $ROOT (emulated second stage: several minutes)"
    rm -rf "$ROOT"
    debootstrap --arch=arm64 --variant=minbase --include=python3,python3-venv,git,ca-certificates \
        "$SUITE" "$ROOT" "$MIRROR" >"$OUT/debootstrap.log" 2>&1 || { tail -20 "$OUT/debootstrap.log"; die "debootstrap"; }
    touch "$ROOT/.pi-check-root"
fi

MOUNTS=""
cleanup() {
    for m in $MOUNTS; do umount -l "$m" 2>/dev/null || true; done
}
trap cleanup EXIT INT TERM
bind() {  # bind $1 at $ROOT$2
    mkdir -p "$ROOT$2"
    mount --bind "$1" "$ROOT$2"
    MOUNTS="$ROOT$2 $MOUNTS"
}
mount -t proc proc "$ROOT/proc" && MOUNTS="$ROOT/proc $MOUNTS"
bind /dev /dev
mount -t tmpfs tmpfs "$ROOT/dev/shm" && MOUNTS="$ROOT/dev/shm $MOUNTS"
cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
# pip in the root trusts what this host trusts (a TLS-inspecting proxy's CA, where there is one)
cp /etc/ssl/certs/ca-certificates.crt "$ROOT/etc/ssl/certs/host-ca-certificates.crt"

arm() {  # run a command in the arm64 root with a clean environment
    chroot "$ROOT" /usr/bin/env -i PATH=/usr/local/bin:/usr/bin:/bin:/usr/sbin:/sbin HOME=/root LANG=C.UTF-8 \
        PIP_CERT=/etc/ssl/certs/host-ca-certificates.crt PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_DEFAULT_TIMEOUT=180 \
        MPLBACKEND=Agg GPIOZERO_PIN_FACTORY=mock "$@"
}

machine=$(arm uname -m)
[ "$machine" = aarch64 ] || die "the root runs as $machine, not aarch64"
pyver=$(arm python3 -c 'import platform; print(platform.python_version())')
debver=$(cat "$ROOT/etc/debian_version")

# --- install as systemd/README.md tells a user ----------------------------------------------------------
commit=$(git -C "$REPO" rev-parse --short HEAD)
git -C "$REPO" diff --quiet HEAD || say "note: uncommitted changes are not checked (the clone takes HEAD $commit)"
say "Debian $debver ($SUITE) $machine, Python $pyver; installing moi $commit as systemd/README.md says"
# the clone is made by this machine's git (a work tree of another clone points outside the root), the rest in the root
rm -rf "$ROOT/opt/moi" && git clone --quiet "$REPO" "$ROOT/opt/moi" || die "git clone"
arm python3 -m venv /opt/moi/.venv || die "python3 -m venv"
if ! arm /opt/moi/.venv/bin/pip install '/opt/moi[pi]' >"$OUT/pip-install.log" 2>&1; then
    tail -30 "$OUT/pip-install.log"
    die "pip install '/opt/moi[pi]' on arm64 (log: $OUT/pip-install.log)"
fi
built=$(sed -n 's/.*Building wheel for \([^ ]*\) .*/\1/p' "$OUT/pip-install.log" | grep -v '^moi$' | sort -u | tr '\n' ' ')
if [ -n "$built" ]; then say "built from source on arm64 (no aarch64 wheel): $built"
else say "every dependency installed from an aarch64 wheel"; fi
arm /opt/moi/.venv/bin/pip list --format=freeze 2>/dev/null |
    grep -i -E '^(numpy|scipy|numba|llvmlite|opencv-python-headless|matplotlib|pymodbus|paho-mqtt|asyncua|lgpio|gpiozero|pysparkplug)==' |
    tr '\n' ' ' | sed 's/^/pi-check: arm64 packages: /; s/ $/\n/'

# --- the same computations on both architectures -------------------------------------------------------
say "moi identify $TRACE (arm64, emulated)"
arm sh -c "cd /opt/moi && /opt/moi/.venv/bin/moi identify $TRACE --rig $TRACE_RIG --json" >"$OUT/identify-arm64.json" ||
    die "moi identify on arm64"
(cd "$REPO" && "$HOST_MOI" identify $TRACE --rig $TRACE_RIG --json) >"$OUT/identify-x86_64.json" ||
    die "moi identify on $(uname -m)"

SIM="--rig $SIM_RIG --inertia 0.02 --effects viscous=2e-4 coulomb=1e-4 --theta0 0.3 --duration 20 --noise 2e-4 --seed 7"
say "moi simulate --seed 7 and moi identify it (arm64, emulated)"
arm sh -c "cd /opt/moi && /opt/moi/.venv/bin/moi simulate $SIM --out /tmp/sim.csv >/dev/null && \
    /opt/moi/.venv/bin/moi identify /tmp/sim.csv --rig $SIM_RIG --json" >"$OUT/sim-identify-arm64.json" ||
    die "moi simulate / identify on arm64"
cp "$ROOT/tmp/sim.csv" "$OUT/sim-arm64.csv"
(cd "$REPO" && "$HOST_MOI" simulate $SIM --out "$OUT/sim-x86_64.csv" >/dev/null &&
    "$HOST_MOI" identify "$OUT/sim-x86_64.csv" --rig $SIM_RIG --json) >"$OUT/sim-identify-x86_64.json" ||
    die "moi simulate / identify on $(uname -m)"

say "moi measure --sim (arm64, emulated)"
arm sh -c "cd /opt/moi && /opt/moi/.venv/bin/moi measure --sim --json --seed 3" >"$OUT/measure-arm64.json" \
    2>"$OUT/measure-arm64.log" || { tail -20 "$OUT/measure-arm64.log"; die "moi measure --sim on arm64"; }

"$(dirname "$HOST_MOI")/python" - "$OUT" "$TRACE" <<'EOF'
import json, sys
out, trace = sys.argv[1], sys.argv[2]
def load(name):
    with open(f"{out}/{name}") as f:
        return json.load(f)
ok = True
def compare(what, a, b):
    """J within 1e-9 relative (ω_n where the rig gives no J); the damping ratio's difference is shown."""
    global ok
    key, unit = ("J", "kg·m²") if b.get("J") is not None else ("omega_n", "rad/s")
    rel = abs(a[key] - b[key]) / abs(b[key]) if a.get(key) is not None else float("inf")
    good = rel <= 1e-9
    ok &= good
    zeta = abs(a["damping_ratio"] - b["damping_ratio"]) / abs(b["damping_ratio"]) if b.get("damping_ratio") else 0.0
    print(f"pi-check: {what}: {key} arm64 = {a[key]!r}, x86_64 = {b[key]!r} {unit}, relative difference {rel:.1e} "
          f"{'ok' if good else 'EXCEEDS 1e-9'} (damping ratio: {zeta:.1e})")
compare(f"identify {trace}", load("identify-arm64.json"), load("identify-x86_64.json"))
with open(f"{out}/sim-arm64.csv", "rb") as a, open(f"{out}/sim-x86_64.csv", "rb") as b:
    same = a.read() == b.read()
print(f"pi-check: simulate --seed 7: the traces are {'byte for byte the same' if same else 'DIFFERENT'}")
ok &= same
compare("identify the simulated trace", load("sim-identify-arm64.json"), load("sim-identify-x86_64.json"))
m = load("measure-arm64.json")
# its trace is sampled in wall-clock time, which emulation slows 20-50 ×: a third of the encoder's replies come
# late and are dropped, and the kept ones' time stamps jitter far more than on a Pi, so its σ (a few 1e-7 of
# J, the statistics alone on a rig whose stiffness is exact) is not the yardstick here: J within 1e-5 of the
# truth is (the product states its J to 1e-3 at best); the z is shown
rel = abs(m["J"] - m["truth"]["J"]) / m["truth"]["J"]
z = abs(m["J"] - m["truth"]["J"]) / m["J_std"] if m.get("J_std") else float("inf")
good = rel <= 1e-5
ok &= good
print(f"pi-check: measure --sim on arm64: J = {m['J']:.9g} ± {m['J_std']:.2g} kg·m², true {m['truth']['J']:g}: "
      f"relative error {rel:.1e} ({z:.1f} of its statistical σ), flags {m.get('flags')} "
      f"{'ok' if good else 'BEYOND 1e-5'}")
sys.exit(0 if ok else 1)
EOF
say "passed on Debian $debver ($SUITE) arm64, Python $pyver"

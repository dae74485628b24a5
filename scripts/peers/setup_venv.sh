#!/usr/bin/env bash
# Usage: scripts/peers/setup_venv.sh
#
# Creates (idempotently) the peer-tools virtualenv `.venv-peers/` in the repo root and
# installs, only when missing or at the wrong version:
#   open3d-cpu  (pinned, see O3D_VERSION)  -- the peer RGB-D pipeline (tensor dense SLAM)
#   evo         (pinned, see EVO_VERSION)  -- trajectory ATE/RPE, the community's reference tool
#   opencv-python-headless (pinned, see CV_VERSION) -- the peer feature odometry (ORB + PnP)
#   numpy       (whatever open3d/evo pull in; installed explicitly if absent)
# Installs python3-venv via apt-get when the venv module is missing.
# Safe to run again (a second run only checks versions) and tolerant of a `.venv-peers/`
# created by someone else (it only adds what is missing).
#
# Env overrides: PEERS_VENV (venv path), PYTHON (interpreter used to create the venv).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VENV="${PEERS_VENV:-$ROOT/.venv-peers}"
PYTHON="${PYTHON:-python3}"
O3D_VERSION="0.20.0"
EVO_VERSION="1.38.1"
CV_VERSION="4.10.0.84"

log() { echo "[setup_venv] $*"; }

# Serialise with other scripts that set up this venv (scripts/evo_check.sh takes the same
# lock file, "$VENV.lock", git-ignored).
exec 9>"$VENV.lock"
if command -v flock >/dev/null 2>&1; then flock 9; fi

if ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
    log "python venv/ensurepip module missing: apt-get install -y python3-venv"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv
fi

if [ ! -x "$VENV/bin/python" ]; then
    log "creating venv $VENV with $("$PYTHON" --version 2>&1)"
    "$PYTHON" -m venv "$VENV"
else
    log "venv $VENV exists ($("$VENV/bin/python" --version 2>&1))"
fi
PY="$VENV/bin/python"
if ! "$PY" -m pip --version >/dev/null 2>&1; then
    log "pip missing in venv: bootstrapping with ensurepip"
    "$PY" -m ensurepip --upgrade
fi

# installed version of a distribution, or empty
dist_version() {
    "$PY" - "$1" <<'PYEOF' 2>/dev/null || true
import sys
from importlib.metadata import version, PackageNotFoundError
try:
    print(version(sys.argv[1]))
except PackageNotFoundError:
    pass
PYEOF
}

want=()
o3d_have="$(dist_version open3d-cpu)"
[ -z "$o3d_have" ] && o3d_have="$(dist_version open3d)"
if [ "$o3d_have" = "$O3D_VERSION" ] && "$PY" -c 'import open3d' >/dev/null 2>&1; then
    log "open3d $o3d_have present"
else
    log "open3d: have '${o3d_have:-none}', want open3d-cpu==$O3D_VERSION"
    want+=("open3d-cpu==$O3D_VERSION")
fi
evo_have="$(dist_version evo)"
if [ -n "$evo_have" ] && [ -x "$VENV/bin/evo_ape" ]; then
    log "evo $evo_have present (any version accepted)"
else
    log "evo: missing, want evo==$EVO_VERSION"
    want+=("evo==$EVO_VERSION")
fi
cv_have="$(dist_version opencv-python-headless)"
if [ "$cv_have" = "$CV_VERSION" ] && "$PY" -c 'import cv2' >/dev/null 2>&1; then
    log "opencv $cv_have present"
else
    log "opencv: have '${cv_have:-none}', want opencv-python-headless==$CV_VERSION"
    want+=("opencv-python-headless==$CV_VERSION")
fi
np_have="$(dist_version numpy)"
if [ -n "$np_have" ]; then
    log "numpy $np_have present"
elif [ ${#want[@]} -eq 0 ]; then
    want+=("numpy")
fi

if [ ${#want[@]} -gt 0 ]; then
    log "pip install ${want[*]}"
    "$PY" -m pip install --disable-pip-version-check -q "${want[@]}"
    if [ -z "$np_have" ] && [ -z "$(dist_version numpy)" ]; then
        "$PY" -m pip install --disable-pip-version-check -q numpy
    fi
else
    log "nothing to install"
fi

log "versions: open3d $("$PY" -c 'import open3d; print(open3d.__version__)' 2>/dev/null | tail -1)," \
    "evo $(dist_version evo), numpy $(dist_version numpy), $("$PY" --version 2>&1)"

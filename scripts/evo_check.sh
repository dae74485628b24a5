#!/usr/bin/env bash
# Compares `webfusion eval` with evo (github.com/MichaelGrupp/evo), the community's reference
# implementation of the TUM ATE/RPE, on the same pair of TUM trajectory files.
#
# Usage:
#   scripts/evo_check.sh EST [GT]     EST against GT (default GT: ../shared/data/tum_fr1_rpy_0-99/groundtruth.txt)
#   scripts/evo_check.sh --selftest [GT]
#                                     generates, deterministically, two estimates from GT (every 3rd
#                                     pose, ±4 ms timestamp jitter, 5 mm / 0.3° noise, a rigid offset;
#                                     the second also scaled by 0.8, plus one pose with no ground
#                                     truth within the max difference) and compares on both.
#
# For each file pair it runs, with --t_max_diff = MAX_DIFF_MS:
#   evo_ape tum GT EST -a     vs  webfusion eval                  (ATE, SE(3) alignment)
#   evo_ape tum GT EST        vs  webfusion eval --no-align       (ATE, no alignment)
#   evo_ape tum GT EST -as    vs  webfusion eval --correct-scale  (ATE, Sim(3) alignment)
#   evo_ape tum GT EST -s     vs  webfusion eval --no-align --correct-scale  (ATE, scale only)
#   evo_rpe tum GT EST --delta DELTA --delta_unit f [-r angle_deg]        vs  RPE of webfusion eval
#   evo_rpe tum GT EST --delta DELTA --delta_unit f -as [-r angle_deg]    vs  RPE of webfusion eval --correct-scale
# and compares rmse, mean, median, std, min, max, the number of pairs, every per-pair ATE error
# and the alignment's translation and scale.
#
# Tolerances (exit 1 if any is exceeded): ATE and its per-pair errors 1e-4 m; RPE translation
# 1e-4 m; RPE rotation 1e-3 deg; alignment translation 1e-4 m, scale 1e-6. Both tools work in
# float64 on the same associations, so agreement is normally ~1e-12; the tolerances only leave
# room for evo reading timestamps as float seconds (association is the same unless two stamps are
# within float rounding of the max difference). Association differs in one corner: evo pairs each
# pose of the shorter trajectory with its nearest stamp (a stamp may be used twice), webfusion
# follows the benchmark's associate.py (greedy, each stamp once); a pair-count mismatch is reported.
#
# Env: WEBFUSION_BIN  prebuilt `webfusion` binary (default: cargo run --release -p webfusion-bridge)
#      MAX_DIFF_MS    association max time difference, ms (default 20, the TUM benchmark's)
#      DELTA          RPE delta in frames (default 1)
#      PEERS_VENV     virtualenv holding evo (default .venv-peers in the repo root; created and
#                     `pip install evo` run if evo_ape is missing)
#      KEEP_TMP=1     keep the scratch directory with evo's zips and webfusion's JSON
set -euo pipefail

usage() { sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; }

selftest=0
positional=()
for arg in "$@"; do
    case "$arg" in
        --selftest) selftest=1 ;;
        -h | --help) usage; exit 0 ;;
        -*) echo "evo_check: unknown option $arg (see --help)" >&2; exit 2 ;;
        *) positional+=("$arg") ;;
    esac
done
abspath() { (cd "$(dirname "$1")" && echo "$(pwd)/$(basename "$1")"); }
need_file() { [ -f "$1" ] || { echo "evo_check: $2 file $1 does not exist" >&2; exit 2; }; }

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ "$selftest" = 1 ]; then
    [ "${#positional[@]}" -le 1 ] || { echo "evo_check: --selftest takes at most a GT file" >&2; exit 2; }
    GT="${positional[0]:-}"
    EST=""
else
    [ "${#positional[@]}" -ge 1 ] && [ "${#positional[@]}" -le 2 ] || { usage >&2; exit 2; }
    EST="${positional[0]}"
    GT="${positional[1]:-}"
    need_file "$EST" estimated
    EST="$(abspath "$EST")"
fi
if [ -z "$GT" ]; then GT="$ROOT/../shared/data/tum_fr1_rpy_0-99/groundtruth.txt"; fi
need_file "$GT" ground-truth
GT="$(abspath "$GT")"
cd "$ROOT"

MAX_DIFF_MS="${MAX_DIFF_MS:-20}"
DELTA="${DELTA:-1}"
VENV="${PEERS_VENV:-$ROOT/.venv-peers}"

# --- evo in a virtualenv (idempotent; the lock serialises with other scripts using this venv) ---
ensure_evo() {
    if [ -x "$VENV/bin/evo_ape" ] && [ -x "$VENV/bin/evo_rpe" ]; then return; fi
    exec 9>"$VENV.lock"
    if command -v flock >/dev/null 2>&1; then flock 9; fi
    if [ ! -x "$VENV/bin/python" ]; then
        echo "[evo_check] creating virtualenv $VENV" >&2
        python3 -m venv "$VENV"
    fi
    if [ ! -x "$VENV/bin/evo_ape" ] || [ ! -x "$VENV/bin/evo_rpe" ]; then
        echo "[evo_check] pip install evo into $VENV" >&2
        "$VENV/bin/python" -m pip install --disable-pip-version-check -q evo
    fi
    exec 9>&-
}
ensure_evo
PY="$VENV/bin/python"
echo "evo $("$PY" -c 'from importlib.metadata import version; print(version("evo"))'), $("$PY" --version 2>&1)"

tmp="$(mktemp -d "${TMPDIR:-/tmp}/evo_check.XXXXXX")"
if [ "${KEEP_TMP:-0}" = 1 ]; then echo "scratch directory: $tmp"; else trap 'rm -rf "$tmp"' EXIT; fi

# The comparison of one directory of results (evo's zips, webfusion's JSON); exit 1 on mismatch.
cat > "$tmp/compare.py" <<'PYEOF'
import io, json, sys, zipfile
import numpy as np

out = sys.argv[1]
ATE_TOL_M, RPE_TRANS_TOL_M, RPE_ROT_TOL_DEG, ALIGN_T_TOL_M, SCALE_TOL = 1e-4, 1e-4, 1e-3, 1e-4, 1e-6

def evo(name):
    with zipfile.ZipFile(f"{out}/{name}.zip") as z:
        stats = json.loads(z.read("stats.json"))
        errors = np.load(io.BytesIO(z.read("error_array.npy")))
        sim3 = np.load(io.BytesIO(z.read("alignment_transformation_sim3.npy"))) if "alignment_transformation_sim3.npy" in z.namelist() else None
    return stats, errors, sim3

def wf(name):
    with open(f"{out}/{name}.json") as f:
        return json.load(f)

failed = []
print(f"  {'comparison':<36} {'statistic':<14} {'evo':>16} {'webfusion':>16} {'|diff|':>9} {'tol':>7}")
def row(label, stat, a, b, tol):
    diff = abs(a - b)
    ok = diff <= tol
    if not ok:
        failed.append(f"{label} {stat}")
    print(f"  {label:<36} {stat:<14} {a:>16.9f} {b:>16.9f} {diff:>9.1e} {tol:>7.0e} {'ok' if ok else 'FAIL'}")

def diff_row(label, stat, diff, tol):
    ok = diff <= tol
    if not ok:
        failed.append(f"{label} {stat}")
    print(f"  {label:<36} {stat:<14} {'':>16} {'':>16} {diff:>9.1e} {tol:>7.0e} {'ok' if ok else 'FAIL'}")

def count_row(label, stat, a, b):
    if a != b:
        failed.append(f"{label} {stat}")
    print(f"  {label:<36} {stat:<14} {a:>16d} {b:>16d} {'':>9} {'exact':>7} {'ok' if a == b else 'FAIL'}")

STATS = ("rmse", "mean", "median", "std", "min", "max")
for evo_name, wf_name, label in (("evo_ape_se3", "wf_se3", "ATE SE(3) align [m]"),
                                 ("evo_ape_none", "wf_none", "ATE no alignment [m]"),
                                 ("evo_ape_sim3", "wf_sim3", "ATE Sim(3) align [m]"),
                                 ("evo_ape_scale", "wf_scale", "ATE scale only [m]")):
    stats, errors, sim3 = evo(evo_name)
    ate = wf(wf_name)["ate"]
    count_row(label, "pairs", len(errors), ate["stats"]["count"])
    for s in STATS:
        row(label, s, stats[s], ate["stats"][f"{s}_m"], ATE_TOL_M)
    ours = np.array([p["error_m"] for p in ate["per_pair"]])
    if len(ours) == len(errors):
        diff_row(label, "per-pair max", float(np.max(np.abs(ours - errors))), ATE_TOL_M)
    if sim3 is not None and wf_name != "wf_none":
        g = ate["gt_from_est"]
        # evo's Sim(3) matrix is [s R | t]; ours is gt_from_est * scale.
        scale_evo = float(np.cbrt(np.linalg.det(sim3[:3, :3])))
        row(label, "align scale", scale_evo, g["scale"], SCALE_TOL)
        if wf_name == "wf_scale":
            continue  # evo saves the whole Sim(3) fit but applies only its scale
        diff_row(label, "align t [m]", float(np.linalg.norm(sim3[:3, 3] - np.array(g["translation_m"]))), ALIGN_T_TOL_M)

for evo_trans, evo_rot, wf_name, label in (("evo_rpe_trans", "evo_rpe_rot", "wf_se3", "RPE"),
                                           ("evo_rpe_trans_sim3", "evo_rpe_rot_sim3", "wf_sim3", "RPE scale-corrected")):
    rpe = wf(wf_name)["rpe"]
    for evo_name, key, unit, tol in ((evo_trans, "translation", "m", RPE_TRANS_TOL_M), (evo_rot, "rotation", "deg", RPE_ROT_TOL_DEG)):
        stats, errors, _ = evo(evo_name)
        sub = f"{label} {key} [{unit}]"
        count_row(sub, "pairs", len(errors), rpe[key]["count"])
        for s in STATS:
            row(sub, s, stats[s], rpe[key][f"{s}_{unit}"], tol)
        ours = np.array(rpe[f"per_pair_{key}_{unit}"])
        if len(ours) == len(errors):
            diff_row(sub, "per-pair max", float(np.max(np.abs(ours - errors))), tol)

if failed:
    print(f"  MISMATCH in {len(failed)} comparisons: " + ", ".join(failed))
    sys.exit(1)
print("  all comparisons within tolerance")
PYEOF

webfusion() {
    if [ -n "${WEBFUSION_BIN:-}" ]; then
        "$WEBFUSION_BIN" "$@"
    else
        cargo run --release -q -p webfusion-bridge --bin webfusion -- "$@"
    fi
}

# Deterministic perturbed estimates: est_world_from_camera = est_from_gt * gt_world_from_camera * noise.
generate() {
    "$PY" - "$GT" "$tmp/est_selftest.txt" "$tmp/est_selftest_scaled.txt" <<'PYEOF'
import math, random, sys

gt_path, out_path, out_scaled_path = sys.argv[1:4]

def qmul(a, b):  # (x, y, z, w)
    ax, ay, az, aw = a; bx, by, bz, bw = b
    return (aw*bx + ax*bw + ay*bz - az*by, aw*by - ax*bz + ay*bw + az*bx,
            aw*bz + ax*by - ay*bx + az*bw, aw*bw - ax*bx - ay*by - az*bz)

def qrot(q, v):
    x, y, z, w = qmul(qmul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)

def axis_angle(axis, angle):
    n = math.sqrt(sum(a * a for a in axis))
    s = math.sin(angle / 2) / n
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2))

rows = []
with open(gt_path) as f:
    for line in f:
        fields = line.replace(",", " ").split()
        if fields and not fields[0].startswith("#"):
            rows.append(fields)
rng = random.Random(20240521)
q_offset = axis_angle((0.3, -0.5, 0.8), math.radians(25.0))
t_offset = (0.5, -1.2, 0.3)
noise_m, noise_rad = 0.005, math.radians(0.3)
for path, scale in ((out_path, 1.0), (out_scaled_path, 0.8)):
    lines = ["# timestamp tx ty tz qx qy qz qw  (evo_check.sh --selftest, scale %r)" % scale]
    for fields in rows[::3]:
        stamp_us = round(float(fields[0]) * 1e6) + rng.randint(-4000, 4000)
        t = [float(v) for v in fields[1:4]]
        q = tuple(float(v) for v in fields[4:8])
        t = [v + rng.gauss(0.0, noise_m) for v in t]
        q_noise = axis_angle([rng.gauss(0.0, 1.0) for _ in range(3)], abs(rng.gauss(0.0, noise_rad)))
        q = qmul(qmul(q_offset, q), q_noise)
        t = [a + b for a, b in zip(qrot(q_offset, [scale * v for v in t]), t_offset)]
        n = math.sqrt(sum(v * v for v in q))
        lines.append("%d.%06d %r %r %r %r %r %r %r" % (stamp_us // 10**6, stamp_us % 10**6, *t, *(v / n for v in q)))
    # A pose 100 ms after the last ground truth: no partner within the max difference.
    last_us = round(float(rows[-1][0]) * 1e6) + 100_000
    lines.append("%d.%06d 0 0 0 0 0 0 1" % (last_us // 10**6, last_us % 10**6))
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("generated %s: %d poses" % (path, len(lines) - 1))
PYEOF
}

compare() {
    local est="$1" name="$2" out="$tmp/$2"
    mkdir -p "$out"
    local max_diff_s
    max_diff_s="$("$PY" -c "print($MAX_DIFF_MS / 1000.0)")"
    local evo_common=(--t_max_diff "$max_diff_s" --no_warnings --silent)
    echo
    echo "== $name: $est against $GT (max time difference $MAX_DIFF_MS ms, RPE delta $DELTA frames)"
    "$VENV/bin/evo_ape" tum "$GT" "$est" -a "${evo_common[@]}" --save_results "$out/evo_ape_se3.zip"
    "$VENV/bin/evo_ape" tum "$GT" "$est" "${evo_common[@]}" --save_results "$out/evo_ape_none.zip"
    "$VENV/bin/evo_ape" tum "$GT" "$est" -as "${evo_common[@]}" --save_results "$out/evo_ape_sim3.zip"
    "$VENV/bin/evo_ape" tum "$GT" "$est" -s "${evo_common[@]}" --save_results "$out/evo_ape_scale.zip"
    local rpe_common=(--delta "$DELTA" --delta_unit f "${evo_common[@]}")
    "$VENV/bin/evo_rpe" tum "$GT" "$est" "${rpe_common[@]}" -r trans_part --save_results "$out/evo_rpe_trans.zip"
    "$VENV/bin/evo_rpe" tum "$GT" "$est" "${rpe_common[@]}" -r angle_deg --save_results "$out/evo_rpe_rot.zip"
    "$VENV/bin/evo_rpe" tum "$GT" "$est" "${rpe_common[@]}" -as -r trans_part --save_results "$out/evo_rpe_trans_sim3.zip"
    "$VENV/bin/evo_rpe" tum "$GT" "$est" "${rpe_common[@]}" -as -r angle_deg --save_results "$out/evo_rpe_rot_sim3.zip"

    local wf_common=(eval --gt "$GT" --est "$est" --max-difference-ms "$MAX_DIFF_MS" --delta-frames "$DELTA")
    webfusion "${wf_common[@]}" --json "$out/wf_se3.json" > "$out/wf_se3.txt"
    webfusion "${wf_common[@]}" --no-align --json "$out/wf_none.json" > "$out/wf_none.txt"
    webfusion "${wf_common[@]}" --correct-scale --json "$out/wf_sim3.json" > "$out/wf_sim3.txt"
    webfusion "${wf_common[@]}" --no-align --correct-scale --json "$out/wf_scale.json" > "$out/wf_scale.txt"
    sed 's/^/  webfusion eval | /' "$out/wf_se3.txt"

    "$PY" "$tmp/compare.py" "$out"
}

# Negative control: the comparison must fail when webfusion's ATE RMSE is off by 2e-4 m.
negative_control() {
    local out="$tmp/$1" bad="$tmp/$1_tampered"
    cp -r "$out" "$bad"
    "$PY" - "$bad/wf_se3.json" <<'PYEOF'
import json, sys
with open(sys.argv[1]) as f:
    report = json.load(f)
report["ate"]["stats"]["rmse_m"] += 2e-4
with open(sys.argv[1], "w") as f:
    json.dump(report, f)
PYEOF
    echo
    echo "== negative control: ATE RMSE of webfusion moved by 2e-4 m must fail the comparison"
    if "$PY" "$tmp/compare.py" "$bad" > "$bad/compare.txt"; then
        echo "  negative control FAILED: the tampered report passed" >&2
        return 1
    fi
    grep -E "FAIL|MISMATCH" "$bad/compare.txt" | sed 's/^ */  /'
    echo "  negative control ok: the comparison caught it"
}

# Each comparison in a subshell with `set -e` in force (it would be off inside `compare || ...`),
# so a failing command stops that comparison and the others still run.
status=0
run_compare() {
    set +e
    (set -e; compare "$@")
    [ $? -eq 0 ] || status=1
    set -e
}
if [ "$selftest" = 1 ]; then
    generate
    run_compare "$tmp/est_selftest.txt" selftest
    run_compare "$tmp/est_selftest_scaled.txt" selftest_scaled
    [ "$status" != 0 ] || negative_control selftest || status=1
else
    run_compare "$EST" given
fi
echo
if [ "$status" = 0 ]; then echo "evo_check: webfusion eval agrees with evo"; else echo "evo_check: webfusion eval DISAGREES with evo" >&2; fi
exit "$status"

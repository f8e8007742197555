#!/usr/bin/env bash
# The CUDA renderer on an NVIDIA GPU in one go: set-up, compile, agreement, speed.
#
#   bash benchmarks/gpu_check.sh            # results under $OUT (default benchmarks/out/gpu_check)
#
# Made for a machine lent for minutes (GPU time is scarce), so every step is guarded by its
# own `timeout`, a failure never stops the next step, and all steps share one time budget
# (GPU_CHECK_BUDGET seconds, default 390: later steps are skipped, and say so, when it runs
# out; GPU_CHECK_SKIP="name ..." skips steps by name). Without a usable GPU it reports
# "no GPU" with the reason and runs the simulator checks instead. Everything measured lands in $OUT, at most 8 files:
#
#   env.txt        card, driver, compute capability, Python and package versions, set-up
#   steps.tsv      each step: name, ok/FAILED/TIMEOUT/skipped, seconds, command
#   agree.log      kernel compile smoke test + GPU-vs-CPU agreement tests (pytest -s)
#   bench.log      benchmarks/render.py --device cuda (foot 256³, foot ×2 512³)
#   gen.log        a generation's rendering through a Session: GPU, and the CPU on 2 threads
#   cli.log        a short `intuitf optimize --device cuda` of the foot
#   results.jsonl  every figure as a JSON line (benchmarks/render.py --json)
#   summary.md     the table of figures against the targets, and the steps' outcomes
#
# Set-up on a machine that has numpy, numba, numba-cuda, scipy, scikit-image, pillow but not
# intuitf's other dependencies: intuitf runs from src/ (PYTHONPATH); the render path and the
# tests need nothing else. Wheels in .gpu/whl (pure Python except pydantic_core; for the CLI:
# cma, pydantic and its needs) are installed into a private folder first, and the volumes are
# read from .gpu/data when it exists (INTUITF_DATA), else from ../shared/data/volumes.
# Made here (both ignored through .git/info/exclude; the device tool's `carry` takes .gpu):
#   mkdir -p .gpu/data .gpu/whl && cp ../shared/data/volumes/{foot,tooth,neghip}_*.raw.gz .gpu/data/
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux2014_x86_64 -d .gpu/whl pynrrd cma pydantic pydantic_core \
#     annotated_types typing_inspection typing_extensions   (pydantic_core: pydantic's pin)
set -u

ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT" || exit 1
OUT=${OUT:-$ROOT/benchmarks/out/gpu_check}
mkdir -p "$OUT"
BUDGET=${GPU_CHECK_BUDGET:-390}
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1
export NUMBA_CACHE_DIR=${NUMBA_CACHE_DIR:-/tmp/intuitf-numba-cache}
SITE=${GPU_CHECK_SITE:-/tmp/intuitf-site}
export PYTHONPATH="$ROOT/src:$SITE${PYTHONPATH:+:$PYTHONPATH}"
if [ -d "$ROOT/.gpu/data" ]; then
    export INTUITF_DATA="$ROOT/.gpu/data"
fi
export INTUITF_DATA=${INTUITF_DATA:-$ROOT/../shared/data/volumes}
FOOT="$INTUITF_DATA/foot_zfp8lossy_256x256x256_uint8.raw.gz"
: >"$OUT/steps.tsv"
: >"$OUT/results.jsonl"

# step NAME LIMIT LOGFILE CMD...: run CMD with at most LIMIT seconds (less if the budget is
# nearly spent), appending its output to $OUT/LOGFILE and its outcome to steps.tsv.
step() {
    local name=$1 limit=$2 log=$3 left rc status t0
    shift 3
    if [[ " ${GPU_CHECK_SKIP:-} " == *" $name "* ]]; then
        printf '%s\tskipped (GPU_CHECK_SKIP)\t0\t%s\n' "$name" "$*" >>"$OUT/steps.tsv"
        return 0
    fi
    left=$((BUDGET - SECONDS))
    if [ "$left" -lt 20 ]; then
        printf '%s\tskipped (time budget spent)\t0\t%s\n' "$name" "$*" >>"$OUT/steps.tsv"
        echo "== $name: skipped, the time budget is spent" | tee -a "$OUT/$log"
        return 0
    fi
    [ "$limit" -gt "$left" ] && limit=$left
    echo "== $name ($(date -u +%T), at most ${limit}s): $*" | tee -a "$OUT/$log"
    t0=$SECONDS
    timeout -k 5 "$limit" "$@" >>"$OUT/$log" 2>&1
    rc=$?
    case $rc in
        0) status=ok ;;
        124 | 137) status="TIMEOUT after ${limit}s" ;;
        *) status="FAILED (exit $rc)" ;;
    esac
    printf '%s\t%s\t%s\t%s\n' "$name" "$status" "$((SECONDS - t0))" "$*" >>"$OUT/steps.tsv"
    echo "   -> $status in $((SECONDS - t0)) s" | tee -a "$OUT/$log"
}

# -- 1. the machine and the software ------------------------------------------------------
{
    echo "date: $(date -u +%FT%TZ)  host: $(uname -srm)  cpus: $(nproc)"
    if command -v nvidia-smi >/dev/null; then
        nvidia-smi --query-gpu=name,driver_version,compute_cap,memory.total,clocks.max.sm,clocks.max.memory,pcie.link.gen.max,pcie.link.width.max \
            --format=csv 2>&1
        nvidia-smi 2>&1 | head -15
    else
        echo "nvidia-smi: not found"
    fi
    command -v nvcc >/dev/null && nvcc --version | tail -2
    if ls "$ROOT"/.gpu/whl/*.whl >/dev/null 2>&1; then
        echo "installing carried wheels into $SITE: $(cd "$ROOT/.gpu/whl" && echo *.whl)"
        $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
            --target "$SITE" "$ROOT"/.gpu/whl/*.whl 2>&1 | tail -5
    fi
    $PY - <<'EOF'
import importlib.metadata as md, platform, sys
print("python", platform.python_version(), sys.executable)
for name in ("numpy", "numba", "numba-cuda", "llvmlite", "cuda-bindings", "cuda-core",
             "cuda-python", "nvidia-cuda-nvcc-cu12", "cuda-toolkit", "scipy", "scikit-image",
             "pillow", "typer", "rich", "pydantic", "cma", "pytest", "pytest-timeout", "vtk"):
    try:
        print(f"{name} {md.version(name)}")
    except md.PackageNotFoundError:
        print(f"{name} (not installed)")
import numpy as np
print("numpy has row_stack:", hasattr(np, "row_stack"))
from intuitf.render.cuda_compat import prepare_numba_cuda
print("NumPy aliases restored for numba-cuda:", prepare_numba_cuda() or "none needed")
def show(what, fn):
    try:
        print(what, fn())
    except Exception as exc:
        print(what, "failed:", type(exc).__name__, str(exc).splitlines()[0] if str(exc) else "")

try:
    from numba import cuda
    print("numba.cuda imported from", cuda.__file__)
except Exception as exc:
    cuda = None
    print("numba.cuda import failed:", type(exc).__name__, exc)
if cuda is not None:
    show("cuda.is_available():", cuda.is_available)
    show("device:", lambda: (cuda.get_current_device().name, cuda.get_current_device().compute_capability))
    show("CUDA driver version:", lambda: cuda.cudadrv.driver.driver.get_version())
    show("runtime version:", lambda: cuda.runtime.get_version())
    show("NVVM version:", lambda: __import__("numba.cuda.cudadrv.nvvm", fromlist=["x"]).NVVM().get_version())
from intuitf.render.device import cuda_unavailable_reason
print("intuitf cuda_unavailable_reason():", cuda_unavailable_reason())
EOF
} >"$OUT/env.txt" 2>&1
cat "$OUT/env.txt"

REASON=$($PY -c "from intuitf.render.device import cuda_unavailable_reason as r; print(r() or '')" 2>&1 | tail -1)
GPU_NAME=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1)
case "$GPU_NAME" in  # the card's spec-sheet memory bandwidth, GB/s
    *H200*) PEAK=4800 ;;
    *H100*SXM* | *"H100 80GB HBM3"*) PEAK=3350 ;;
    *H100*PCIe*) PEAK=2000 ;;
    *A100*80GB*) PEAK=2039 ;;
    *) PEAK= ;;
esac
PEAK_ARGS=()
[ -n "$PEAK" ] && PEAK_ARGS=(--peak-bandwidth "$PEAK")
VTK_ARGS=(--no-vtk)
$PY -c "import vtk" >/dev/null 2>&1 && VTK_ARGS=()
JSON=(--json "$OUT/results.jsonl")

if [ -n "$REASON" ]; then
    echo "no GPU: $REASON" | tee -a "$OUT/env.txt"
    printf 'gpu\tno GPU: %s\t0\t-\n' "$REASON" >>"$OUT/steps.tsv"
    # What still runs without one: the CUDA kernels under Numba's simulator (as in CI).
    step simulator 900 agree.log $PY -m pytest tests/render/test_cuda_sim.py -q -x \
        -p no:cacheprovider -o addopts=
    # The benchmark must refuse in one line, measuring nothing.
    step bench-says-no-gpu 60 bench.log bash -c "$PY benchmarks/render.py --device cuda \
        --volumes foot 2>&1 | tee /dev/stderr | grep -q 'no usable NVIDIA GPU here'"
else
    # -- 2. compile every kernel once on a small volume, GPU against CPU -------------------
    step compile 150 agree.log $PY - <<'EOF'
import time
import numpy as np
from intuitf.render import Camera, VolumeRenderer
from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import phantom

vol = phantom(size=48)
tf = GaussianTF((Gaussian(0.45, 0.08, 0.4, (1.0, 0.6, 0.3)), Gaussian(0.8, 0.05, 0.9, (0.9, 0.9, 1.0))))
cam = Camera(azimuth=30, elevation=20)
for shading in (False, True):
    t = time.perf_counter()
    g = VolumeRenderer(vol, device="cuda", size=64, shading=shading)
    c = VolumeRenderer(vol, device="cpu", size=64, shading=shading)
    a = g.render(tf, cam); gc = g.sample_cache(cam); m = gc.render_many([tf, tf])
    att = gc.attribution(tf); pk = gc.pick(tf, 32, 32); rd = gc.bytes_read([tf])
    b = c.render(tf, cam); cc = c.sample_cache(cam)
    d1 = np.abs(a.astype(int) - b).max(); d2 = np.abs(m[0].astype(int) - cc.render(tf)).max()
    print(f"shading={shading}: all kernels compiled and ran in {time.perf_counter() - t:.1f} s;"
          f" max diff march {d1}, cache {d2} levels; pick {pk} vs {cc.pick(tf, 32, 32)};"
          f" attribution max diff {np.abs(att - cc.attribution(tf)).max():.1e}")
EOF
    # -- 3. agreement on real volumes (the tests skipped without a GPU) --------------------
    step agreement 200 agree.log $PY -m pytest tests/render/test_cuda_sim.py -s -q \
        -k gpu_agrees -p no:cacheprovider -o addopts= -rA
    # -- 4. speed: a population of 50 at 256², 512², 1024² on the 256³ foot ----------------
    step bench-foot 150 bench.log $PY benchmarks/render.py --device cuda --volumes foot \
        --sizes 256,512,1024 --cpu-candidates 3 --repeat 5 "${VTK_ARGS[@]}" "${PEAK_ARGS[@]}" "${JSON[@]}"
    # -- 5. a generation's rendering through a Session: GPU, then the CPU on two threads ---
    step generation-cuda 90 gen.log $PY benchmarks/render.py --generation --device cuda \
        --generations 4 "${JSON[@]}"
    step generation-cpu-2threads 120 gen.log env NUMBA_NUM_THREADS=2 $PY benchmarks/render.py \
        --generation --device cpu --generations 3 "${JSON[@]}"
    # -- 6. the 512³ upsampled foot ---------------------------------------------------------
    step bench-foot512 150 bench.log $PY benchmarks/render.py --device cuda --volumes foot512 \
        --sizes 256,512,1024 --cpu-candidates 2 --repeat 3 "${VTK_ARGS[@]}" "${PEAK_ARGS[@]}" "${JSON[@]}"
    # -- 7. the command line, end to end ----------------------------------------------------
    RUN=/tmp/intuitf-gpu-run
    rm -rf "$RUN" && mkdir -p "$RUN"
    $PY -c "
import numpy as np; from PIL import Image
y, x = np.mgrid[0:256, 0:256] / 255
Image.fromarray((np.stack([x, y, (x + y) / 2], -1) * 255).astype(np.uint8)).save('$RUN/ref.png')
" >>"$OUT/cli.log" 2>&1
    step cli-optimize 90 cli.log $PY -m intuitf optimize "$FOOT" --evaluator metric \
        --image "$RUN/ref.png" --population 50 --generations 3 --device cuda -o "$RUN/out"
    [ -f "$RUN/out/journal.jsonl" ] && $PY - "$RUN/out/journal.jsonl" >>"$OUT/cli.log" 2>&1 <<'EOF'
import json, sys
for line in open(sys.argv[1]):
    e = json.loads(line)
    if e.get("type") == "generation":
        print(f"journal: generation {e['generation']} took {e.get('seconds', float('nan')):.2f} s"
              f" (stage {e.get('stage')}, {len(e.get('candidates', []))} candidates)")
EOF
fi

# -- 8. summary -------------------------------------------------------------------------------
$PY - "$OUT" "$GPU_NAME" "$REASON" >"$OUT/summary.md" 2>&1 <<'EOF'
import json, statistics, sys
from pathlib import Path

out, gpu, reason = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
rows = [json.loads(l) for l in (out / "results.jsonl").read_text().splitlines() if l.strip()]
env = (out / "env.txt").read_text()
print("# intuitf CUDA renderer: GPU check\n")
print(f"GPU: {gpu or 'none'}" + (f" — no GPU: {reason}" if reason else ""))
for line in env.splitlines():
    if line.startswith(("name,", "python ", "numpy ", "numba ", "numba-cuda ", "CUDA driver",
                        "NVVM", "runtime", "device:", "NumPy aliases", "cuda-bindings ")):
        print(f"- {line}")
for line in env.splitlines():
    if "," in line and gpu and line.startswith(gpu):
        print(f"- nvidia-smi: {line}")
render = [r for r in rows if r.get("kind") == "render"]
if render:
    print("\n`python benchmarks/render.py --device cuda` (population 50 random 5-Gaussian TFs,"
          " one launch; CPU: the same machine, all its cores)\n")
    print("| volume | picture | shading | ms/candidate end to end | kernel µs/candidate |"
          " cache build ms | new camera ms | MB read/candidate | % of peak bandwidth |"
          " CPU ms/candidate | agreement (mean/max levels, PSNR) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in render:
        ag = (f"{r['agree_mean']:.2f}/{r['agree_max']}, {r['agree_psnr']:.1f} dB"
              if "agree_mean" in r else "-")
        print(f"| {r['volume']} {tuple(r.get('dims', ()))} | {r['size']}² |"
              f" {'yes' if r['shading'] else 'no'} | {r['per_cand_ms']:.3f} |"
              f" {r['kernel_us']:.0f} | {r['build_ms']:.1f} | {r['new_cam_ms']:.1f} |"
              f" {r['read_mb']:.2f} | {r.get('bw_pct', float('nan')):.0f} |"
              f" {r.get('cpu_ms', float('nan')):.1f} | {ag} |")
    if render[0].get("peak_gbs"):
        print(f"\nPeak memory bandwidth used for %: {render[0]['peak_gbs']:.0f} GB/s.")
    foot = [r for r in render if "512" not in r["volume"] and "×2" not in r["volume"]]
    for size, limit in ((256, 0.2), (512, 1.0)):
        for r in foot:
            if r["size"] == size and r["shading"]:
                ok = "met" if r["per_cand_ms"] <= limit else "MISSED"
                print(f"- target ≤ {limit} ms/candidate at {size}² shaded (foot):"
                      f" {r['per_cand_ms']:.3f} ms end to end, kernel {r['kernel_us'] / 1e3:.3f}"
                      f" ms — {ok}")
gens = [r for r in rows if r.get("kind") == "generation"]
if gens:
    g0 = gens[0]
    print(f"\n`python benchmarks/render.py --generation` (Session, foot 256³, population"
          f" {g0['population']}, {g0['size']}² shaded; the render jobs of each generation)\n")
    print("| device | threads | generation | rendering ms | step s |")
    print("|---|---|---|---|---|")
    for r in gens:
        print(f"| {r['device']} | {r['threads']} | {r['generation']} | {r['render_ms']:.1f} |"
              f" {r['step_s']:.2f} |")
    steady = {}
    for dev in ("cuda", "cpu"):
        v = [r["render_ms"] for r in gens if r["device"] == dev and r["generation"] > 0]
        if v:
            steady[dev] = statistics.median(v)
    if len(steady) == 2:
        x = steady["cpu"] / steady["cuda"]
        print(f"\n- a generation's rendering (median of generations ≥ 1): GPU"
              f" {steady['cuda']:.1f} ms, CPU on 2 threads {steady['cpu']:.1f} ms: {x:.0f}×"
              f" — target ≥ 50×: {'met' if x >= 50 else 'MISSED'}")
print("\n## Steps\n\n| step | outcome | s | command |\n|---|---|---|---|")
for line in (out / "steps.tsv").read_text().splitlines():
    p = line.split("\t")
    cmd = p[3].replace("|", "\\|") if len(p) > 3 else ""
    print(f"| {p[0]} | {p[1]} | {p[2] if len(p) > 2 else ''} | `{cmd}` |")
EOF
cat "$OUT/summary.md"
for f in agree.log bench.log gen.log cli.log; do
    [ -f "$OUT/$f" ] && grep -E "FAIL|Error|error:|Traceback|passed|failed|skipped" "$OUT/$f" | tail -8 | sed "s|^|$f: |"
done
echo "gpu_check: done in $SECONDS s; results in $OUT"

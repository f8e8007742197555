"""Peak resident memory of ``intuitf serve`` and ``intuitf optimize`` on a clinical-size CT.

Run: ``python benchmarks/memory.py`` (to measure another checkout, put its ``src`` first:
``PYTHONPATH=/tmp/before/src python benchmarks/memory.py``) (options: ``--dims X Y Z``, ``--population``,
``--generations``, ``--view-size``, ``--device``, ``--only serve|optimize``, ``--work DIR``).

The volume is the CT foot of ``$INTUITF_DATA`` (256³ uint8) upsampled trilinearly to
512×512×614 and written as a 12-bit uint16 raw file (``foot_512x512x614_uint16.raw``, 322 MB)
into the work folder (default ``$TMPDIR/intuitf-memory``); it is made once and reused, and
never belongs in the repository.

Measured, each in a fresh process of its own (peak resident set, ``VmHWM`` of the server,
``ru_maxrss`` of optimize):

- ``intuitf serve VOLUME`` with one run going (population 8, 2 generations, the offline metric
  judge), and while it goes: six full view frames of the run's best at 512² from six sides
  (WebSocket), six drag frames, a pick, the features strip and a hand-edit preview (a changed
  TF rendered by ``/api/tf/preview``), all at 512². The peak is printed after each step.
  Target: at most 4 GB.
- ``intuitf optimize VOLUME`` with the same settings. Target: at most 2.5 GB.

Background: a 512×512×614 volume is 0.64 GB as float32 voxels (the normalised data every
renderer reads) and its int16 gradient 0.97 GB; a shaded sample cache at 512² is about
4 bytes per sample along every ray.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("INTUITF_DATA", ROOT / ".." / "shared" / "data" / "volumes"))
FOOT = "foot_zfp8lossy_256x256x256_uint8.raw.gz"
GB = 1024**3


def make_volume(work: Path, dims: tuple[int, int, int]) -> Path:
    """The foot upsampled to ``dims`` (x, y, z) as 12-bit uint16 raw (made once)."""
    x, y, z = dims
    out = work / f"foot_{x}x{y}x{z}_uint16.raw"
    if out.exists() and out.stat().st_size == x * y * z * 2:
        return out
    from scipy.ndimage import zoom

    from intuitf.volume import load_volume

    src = load_volume(DATA / FOOT).data  # float32 [0, 1], (z, y, x)
    factors = (z / src.shape[0], y / src.shape[1], x / src.shape[2])
    print(f"making {out.name} (trilinear upsampling of the foot, once) ...", flush=True)
    up = zoom(src, factors, order=1, output=np.float32)
    tmp = out.with_suffix(".part")
    with open(tmp, "wb") as f:
        for k in range(0, up.shape[0], 32):  # slabs: no second full-size copy
            slab = np.clip(up[k : k + 32] * 4095.0 + 0.5, 0, 4095).astype("<u2")
            f.write(slab.tobytes())
    tmp.replace(out)
    return out


def device_flag(args) -> list[str]:
    """``--device D`` when one was asked for (older versions of ``serve`` had no such flag)."""
    return ["--device", args.device] if args.device else []


def status_kb(pid: int, key: str) -> int:
    """A ``/proc/PID/status`` figure in kB (VmRSS, VmHWM)."""
    text = Path(f"/proc/{pid}/status").read_text()
    m = re.search(rf"^{key}:\s+(\d+) kB", text, re.M)
    return int(m.group(1)) if m else 0


def gb(kb: int) -> str:
    return f"{kb * 1024 / GB:.2f}"


def measure_serve(volume: Path, args, work: Path) -> list[tuple[str, int, int, float]]:
    """Steps of a served session: (step, resident kB, peak kB, seconds the step took)."""
    import httpx
    from websockets.sync.client import connect

    runs = Path(tempfile.mkdtemp(prefix="serve-runs-", dir=work))
    cmd = [sys.executable, "-m", "intuitf", "serve", str(volume), "--runs", str(runs),
           "--no-browser", *device_flag(args)]  # fmt: skip
    server = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})  # fmt: skip
    steps: list[tuple[str, int, int, float]] = []
    t_step = time.perf_counter()

    def mark(what: str) -> None:
        nonlocal t_step
        now = time.perf_counter()
        rss, hwm = status_kb(server.pid, "VmRSS"), status_kb(server.pid, "VmHWM")
        steps.append((what, rss, hwm, now - t_step))
        print(f"  {what:<44} resident {gb(rss):>5} GB  peak {gb(hwm):>5} GB  "
              f"({now - t_step:.1f} s)", flush=True)  # fmt: skip
        t_step = now

    try:
        url = None
        assert server.stdout is not None
        for line in server.stdout:
            m = re.search(r"(http://\S+)/\?token=(\S+)", line)
            if m:
                url, token = m.group(1), m.group(2)
                break
        if url is None:
            raise SystemExit(f"the server did not start: {server.wait()}")
        headers = {"Authorization": f"token {token}"}
        ws_url = url.replace("http://", "ws://") + f"/api/view?token={token}"
        with httpx.Client(base_url=url, headers=headers, timeout=1800) as c:
            vols = c.get("/api/volumes").json()
            vid = next(v["id"] for v in vols if volume.stem in (v.get("name") or v["id"]))
            hist = c.get(f"/api/volumes/{vid}/histogram").json()
            mark("started, volume loaded")
            settings = {"population": args.population, "generations": args.generations}
            r = c.post("/api/runs", json={"volume": vid, "settings": settings,
                                          "intent": "opaque white bone, faint red skin"})  # fmt: skip
            r.raise_for_status()
            name = r.json()["name"]
            while True:  # the first generation's gallery (the run goes on)
                d = c.get(f"/api/runs/{name}").json()
                if d.get("gallery") or d["info"]["status"] != "running":
                    break
                time.sleep(0.5)
            if not d.get("gallery"):
                raise SystemExit(f"the run ended with no gallery: {d['info']}")
            qid = d["gallery"][0]["qid"]
            run, cid = qid.split("/")
            mark(f"run {name}: first generation judged")
            size = args.view_size
            cams = [{"azimuth": a, "elevation": e} for a, e in
                    ((0, 0), (30, 20), (90, 10), (150, -10), (210, 30), (300, 0))]  # fmt: skip
            with connect(ws_url, open_timeout=60, max_size=None) as ws:
                for quality in ("full", "drag"):
                    for i, cam in enumerate(cams):
                        ws.send(json.dumps({"req": i, "target": {"candidate": qid}, "size": size,
                                            "shaded": True, "background": [0, 0, 0],
                                            "quality": quality, "camera": cam}))  # fmt: skip
                        head = json.loads(ws.recv(timeout=1800))
                        if "error" in head:
                            raise SystemExit(f"view frame: {head}")
                        ws.recv(timeout=1800)
                    mark(f"six {quality} view frames at {size}²")
            cam = cams[1]
            body = {"camera": cam, "x": size // 2, "y": size // 2, "size": size, "shaded": True}
            c.post(f"/api/candidates/{run}/{cid}/pick", json=body).raise_for_status()
            mark(f"pick at {size}²")
            body = {"camera": cam, "size": size, "shaded": True}
            c.post(f"/api/candidates/{run}/{cid}/features", json=body).raise_for_status()
            mark(f"features strip at {size}²")
            tf = c.get(f"/api/candidates/{run}/{cid}").json()["tf"]
            for g in tf["gaussians"]:  # a hand edit: every Gaussian a little higher
                g["height"] = min(1.0, float(g["height"]) * 1.5)
            body = {"volume": vid, "tf": tf, "camera": cam, "size": size, "shaded": True}
            c.post("/api/tf/preview", json=body).raise_for_status()
            mark(f"hand-edit preview at {size}²")
            while c.get(f"/api/runs/{name}").json()["info"]["status"] == "running":
                time.sleep(0.5)
            mark("run ended")
        del hist
    finally:
        server.terminate()
        try:
            server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
    return steps


def measure_optimize(volume: Path, args, work: Path) -> tuple[int, float]:
    """Peak resident kB and seconds of ``intuitf optimize`` on the volume."""
    out = Path(tempfile.mkdtemp(prefix="optimize-", dir=work)) / "run"
    cmd = [sys.executable, "-m", "intuitf", "optimize", str(volume), "--text",
           "opaque white bone, faint red skin", "--population", str(args.population),
           "--generations", str(args.generations), *device_flag(args), "-o", str(out)]  # fmt: skip
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        err = proc.stderr.read() if proc.stderr else ""
        raise SystemExit(f"optimize failed ({proc.returncode}): {err[-2000:]}")
    return int(usage.ru_maxrss), time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dims", type=int, nargs=3, default=(512, 512, 614), metavar=("X", "Y", "Z"))
    ap.add_argument("--population", type=int, default=8)
    ap.add_argument("--generations", type=int, default=2)
    ap.add_argument("--view-size", type=int, default=512)
    ap.add_argument("--device", default=None,
                    help="auto, cpu or cuda (default: the commands' own default)")  # fmt: skip
    ap.add_argument("--only", choices=("serve", "optimize"), default=None)
    ap.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "intuitf-memory")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    volume = make_volume(args.work, tuple(args.dims))
    print(f"volume {volume} ({volume.stat().st_size / 1e6:.0f} MB on disk); run: population "
          f"{args.population}, {args.generations} generations, metric judge; views at "
          f"{args.view_size}²; device {args.device or 'default'}; {os.cpu_count()} cores")  # fmt: skip
    rows = []
    if args.only in (None, "serve"):
        print("intuitf serve:")
        steps = measure_serve(volume, args, args.work)
        rows.append(("intuitf serve (run + views, drag, pick, features, edit)",
                     max(s[2] for s in steps), 4.0))  # fmt: skip
    if args.only in (None, "optimize"):
        print("intuitf optimize:")
        peak, secs = measure_optimize(volume, args, args.work)
        print(f"  peak {gb(peak)} GB ({secs:.0f} s)")
        rows.append(("intuitf optimize", peak, 2.5))
    print()
    print(f"{'process':<58}{'peak GB':>8}{'target':>8}{'met':>5}")
    for what, kb, target in rows:
        ok = "yes" if kb * 1024 / GB <= target else "NO"
        print(f"{what:<58}{gb(kb):>8}{'<= ' + str(target):>8}{ok:>5}")


if __name__ == "__main__":
    main()

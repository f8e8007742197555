"""How long reading volumes takes: real raw.gz files, max_dim downsampling, the phantom,
and the same volume in each file format.

Run: ``python benchmarks/bench_volume_load.py`` (uses INTUITF_DATA, default ../shared/data/volumes).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from intuitf.volume import load_volume, phantom

DATA = Path(
    os.environ.get(
        "INTUITF_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "volumes"
    )
)


def best_of(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    load_volume("phantom")  # warm imports
    print(f"{'case':<58}{'seconds':>9}{'Mvox/s':>9}")
    rows = []
    for name in ("tooth_103x94x161_uint8.raw.gz", "ctheadstanford_256x256x113_uint16.raw.gz",
                 "foot_zfp8lossy_256x256x256_uint8.raw.gz"):  # fmt: skip
        p = DATA / name
        if not p.exists():
            continue
        v = load_volume(p)
        n = np.prod(v.dims) / 1e6
        rows.append((f"load {name}", best_of(lambda p=p: load_volume(p)), n))
        rows.append((f"load {name} max_dim=128",
                     best_of(lambda p=p: load_volume(p, max_dim=128)), n))  # fmt: skip
    for size in (96, 192):
        rows.append((f"phantom({size})", best_of(lambda s=size: phantom(s)), size**3 / 1e6))

    ref = phantom(128)
    arr = np.rint(ref.to_original(ref.data)).astype(np.uint8)
    with tempfile.TemporaryDirectory() as d:
        import nibabel as nib
        import nrrd
        import SimpleITK as sitk

        from intuitf.volume.readers.cvol import write_cvol

        d = Path(d)
        arr.tofile(d / "p_128x128x128_uint8.raw")
        nrrd.write(str(d / "p.nrrd"), arr, index_order="C")
        nib.save(nib.Nifti1Image(arr.transpose(2, 1, 0).copy(), np.eye(4)), str(d / "p.nii.gz"))
        sitk.WriteImage(sitk.GetImageFromArray(arr), str(d / "p.mha"))
        np.save(d / "p.npy", arr)
        write_cvol(d / "p.cvol", arr)
        try:
            import vtk
            from vtk.util import numpy_support as ns

            img = vtk.vtkImageData()
            img.SetDimensions(128, 128, 128)
            img.GetPointData().SetScalars(ns.numpy_to_vtk(arr.ravel(), deep=True))
            w = vtk.vtkXMLImageDataWriter()
            w.SetFileName(str(d / "p.vti"))
            w.SetInputData(img)
            w.Write()
        except ImportError:
            pass
        for f in sorted(d.iterdir()):
            rows.append((f"load 128^3 uint8 {f.suffix or f.name}",
                         best_of(lambda f=f: load_volume(f)), 128**3 / 1e6))  # fmt: skip
    for label, secs, mvox in rows:
        print(f"{label:<58}{secs:>9.3f}{mvox / secs:>9.1f}")


if __name__ == "__main__":
    main()

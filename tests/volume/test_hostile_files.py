"""Files a new user may hand over by mistake: empty, cut off, corrupt, looping links, extreme
values. Each gives one clear VolumeError that names the real problem (issue 8, item 5)."""

from __future__ import annotations

import gzip
import os
import subprocess
import sys

import numpy as np
import pytest

from intuitf.errors import VolumeError
from intuitf.volume import Volume, load_volume


def _intuitf(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "intuitf", *args],
        capture_output=True,
        text=True,
        timeout=240,
        cwd=cwd,
    )


@pytest.mark.parametrize("name", ["empty.nrrd", "empty.nhdr", "empty.raw", "empty.mha"])
def test_empty_file_says_it_is_empty(tmp_path, name):
    p = tmp_path / name
    p.write_bytes(b"")
    with pytest.raises(VolumeError, match=r"empty \(0 bytes\)"):
        load_volume(p, shape=(2, 2, 2), dtype="uint8")


def test_nrrd_header_cut_off_before_its_first_line(tmp_path):
    p = tmp_path / "cut.nrrd"
    p.write_bytes(b"NRRD0004")  # no newline: pynrrd runs out of lines
    with pytest.raises(VolumeError):
        load_volume(p)


@pytest.mark.parametrize("command", ["info", "render", "optimize"])
def test_empty_nrrd_in_every_command_is_one_message(tmp_path, command):
    p = tmp_path / "empty.nrrd"
    p.write_bytes(b"")
    extra = {
        "info": [],
        "render": ["-o", str(tmp_path / "x.png")],
        "optimize": ["-o", str(tmp_path / "run")],
    }[command]
    proc = _intuitf(command, str(p), *extra)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "StopIteration" not in proc.stderr
    assert "empty (0 bytes)" in " ".join(proc.stderr.split())  # rich wraps long lines


def test_symlink_loop_is_reported_as_a_loop(tmp_path):
    a, b = tmp_path / "a_4x4x4_uint8.raw", tmp_path / "b_4x4x4_uint8.raw"
    os.symlink(b.name, a)
    os.symlink(a.name, b)
    with pytest.raises(VolumeError, match="loop of symbolic links"):
        load_volume(a)


def test_dangling_symlink_names_its_target(tmp_path):
    a = tmp_path / "a_4x4x4_uint8.raw"
    os.symlink("gone_4x4x4_uint8.raw", a)
    with pytest.raises(VolumeError, match="gone_4x4x4_uint8.raw, which does not exist"):
        load_volume(a)


def test_truncated_raw_gz_says_truncated_not_a_made_up_size(tmp_path):
    rng = np.random.default_rng(0)
    data = rng.integers(0, 20, size=(64, 64, 64), dtype=np.uint8).tobytes()
    z = gzip.compress(data)
    p = tmp_path / "cut_64x64x64_uint8.raw.gz"
    p.write_bytes(z[: len(z) // 2])
    with pytest.raises(VolumeError) as ei:
        load_volume(p)
    msg = str(ei.value)
    assert "truncated" in msg and "262144 bytes" in msg
    # The last four bytes of a cut-off file are no gzip trailer: no size read from them.
    bogus = int.from_bytes(z[len(z) // 2 - 4 : len(z) // 2], "little")
    assert str(bogus) not in msg and "decompressed size is" not in msg


def test_raw_gz_of_the_wrong_size_gives_its_real_size(tmp_path):
    p = tmp_path / "v_10x10x10_uint8.raw.gz"
    p.write_bytes(gzip.compress(bytes(999)))
    with pytest.raises(VolumeError, match="decompressed size is 999 bytes"):
        load_volume(p)


def test_corrupt_mha_gives_metaio_reason_and_no_cpp_output(tmp_path):
    p = tmp_path / "bad.mha"
    p.write_bytes(
        b"ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\nElementType = MET_UCHAR\n"
        b"ElementDataFile = LOCAL\n" + bytes(10)
    )
    proc = _intuitf("info", str(p))
    assert proc.returncode == 2
    assert "truncated or corrupt" in " ".join(proc.stderr.split())  # rich wraps long lines
    assert "No such file" not in proc.stderr
    # SimpleITK's C++ message is folded into ours, not printed on its own line first.
    assert proc.stderr.lstrip().startswith("error:"), proc.stderr
    assert "Traceback" not in proc.stderr


def test_empty_npz_says_it_holds_no_arrays(tmp_path):
    p = tmp_path / "e.npz"
    np.savez(p)
    with pytest.raises(VolumeError, match="no arrays"):
        load_volume(p)
    q = tmp_path / "s.npz"
    np.savez(q, spacing=np.array([1.0, 1.0, 2.0]))
    with pytest.raises(VolumeError, match="only a 'spacing' array"):
        load_volume(q)


def _extreme(dtype=np.float64) -> np.ndarray:
    rng = np.random.default_rng(1)
    a = rng.random((12, 12, 12)).astype(dtype)
    a[0, 0, 0] = 1e308
    a[1, 1, 1] = -1e308
    return a


def test_extreme_finite_values_are_replaced_with_a_note():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow in the arithmetic
        vol = Volume.from_array(_extreme())
    lo, hi = vol.value_range
    assert 0.0 <= lo < 0.01 and 0.99 < hi <= 1.0
    assert np.isfinite(vol.data).all() and vol.data.std() > 0.2
    assert any("beyond" in n and "1e+308" in n for n in vol.notes)


def test_only_extreme_values_of_both_signs_are_refused():
    a = np.full((4, 4, 4), 1e308)
    a[0] = -1e308
    with pytest.raises(VolumeError, match="too wide"):
        Volume.from_array(a)


def test_extreme_but_computable_range_is_kept():
    a = np.full((4, 4, 4), 1.0e308)
    a[0] = 1.2e308
    vol = Volume.from_array(a)
    assert vol.value_range == (1.0e308, 1.2e308)
    assert set(np.unique(vol.data)) == {0.0, 1.0}


def test_float32_near_its_limits_normalises_without_overflow():
    a = np.linspace(-3.4e38, 3.4e38, 4 * 4 * 4, dtype=np.float32).reshape(4, 4, 4)
    vol = Volume.from_array(a)
    assert np.isfinite(vol.data).all()
    assert vol.data.min() == 0.0 and vol.data.max() == 1.0


def test_extreme_values_with_downsampling(tmp_path):
    p = tmp_path / "ext.npy"
    np.save(p, _extreme())
    vol = load_volume(p, max_dim=6)
    assert vol.dims == (6, 6, 6)
    assert np.isfinite(vol.data).all() and vol.data.std() > 0.05
    assert any("beyond" in n for n in vol.notes)


def test_render_of_extreme_volume_is_not_black(tmp_path):
    from PIL import Image

    p = tmp_path / "ext.npy"
    np.save(p, _extreme())
    out = tmp_path / "ext.png"
    proc = _intuitf("render", str(p), "-o", str(out), "--size", "48")
    assert proc.returncode == 0, proc.stderr
    assert np.asarray(Image.open(out)).max() > 40
    assert "beyond" in proc.stderr


def test_optimize_on_extreme_volume_finishes(tmp_path):
    p = tmp_path / "ext.npy"
    np.save(p, _extreme())
    run = tmp_path / "run"
    proc = _intuitf("optimize", str(p), "--population", "4", "--generations", "1",
                    "--size", "32", "--output-size", "32", "--top", "1", "-o", str(run))  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (run / "best" / "rank01.tf.png").exists()  # the TF plot, which used to crash

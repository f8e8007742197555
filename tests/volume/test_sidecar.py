"""A raw file's proportions from a sidecar (JSON or a detached .nhdr), and a note that says
exactly what fixes the picture when nothing gives them (issue 8, item 7)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from intuitf.errors import VolumeError
from intuitf.volume import load_volume

A = (np.arange(4 * 6 * 8).reshape(8, 6, 4) * 5 % 251).astype(np.uint16)  # [z, y, x]


def test_json_sidecar_gives_spacing_shape_type_and_byte_order(tmp_path):
    p = tmp_path / "ct.raw"
    A.astype(">u2").tofile(p)
    (tmp_path / "ct.json").write_text(
        json.dumps({"spacing": [0.5, 0.5, 2], "shape": [4, 6, 8], "dtype": "uint16",
                    "byte_order": "big"})
    )  # fmt: skip
    vol = load_volume(p)
    assert vol.spacing == (0.5, 0.5, 2.0) and vol.dims == (4, 6, 8)
    assert vol.value_range == (float(A.min()), float(A.max()))
    assert any("From ct.json" in n for n in vol.notes)
    assert not any("no voxel spacing" in n for n in vol.notes)


def test_sidecar_next_to_a_named_raw_gz_only_adds_spacing(tmp_path):
    import gzip

    p = tmp_path / "head_4x6x8_uint16.raw.gz"
    p.write_bytes(gzip.compress(A.astype("<u2").tobytes()))
    (tmp_path / "head_4x6x8_uint16.raw.gz.json").write_text('{"spacing": [1, 1, 2.5]}')
    vol = load_volume(p)
    assert vol.spacing == (1.0, 1.0, 2.5) and vol.dims == (4, 6, 8)


def test_options_win_over_the_sidecar(tmp_path):
    p = tmp_path / "ct_4x6x8_uint16.raw"
    A.astype("<u2").tofile(p)
    (tmp_path / "ct_4x6x8_uint16.json").write_text('{"spacing": [0.5, 0.5, 2]}')
    vol = load_volume(p, spacing=(1.0, 2.0, 3.0))
    assert vol.spacing == (1.0, 2.0, 3.0)
    assert not any("From ct" in n for n in vol.notes)


def test_detached_nhdr_pointing_at_the_raw_file(tmp_path):
    p = tmp_path / "scan.dat.raw"
    A.astype(">u2").tofile(p)
    (tmp_path / "header.nhdr").write_text(
        "NRRD0004\ntype: unsigned short\ndimension: 3\nsizes: 4 6 8\n"
        "space directions: (0.7,0,0) (0,0.7,0) (0,0,1.5)\nencoding: raw\nendian: big\n"
        f"data file: {p.name}\n"
    )
    (tmp_path / "other.nhdr").write_text(
        "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: x.raw\n"
    )
    vol = load_volume(p)
    assert vol.dims == (4, 6, 8)
    np.testing.assert_allclose(vol.spacing, (0.7, 0.7, 1.5))
    assert vol.value_range == (float(A.min()), float(A.max()))  # big-endian read right
    assert any("From header.nhdr" in n for n in vol.notes)


def test_nhdr_with_a_byte_skip_sends_the_user_to_the_header(tmp_path):
    p = tmp_path / "s_4x6x8_uint16.raw"
    A.astype("<u2").tofile(p)
    (tmp_path / "s.nhdr").write_text(
        "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 4 6 8\nencoding: raw\nbyte skip: 16\n"
        f"data file: {p.name}\n"
    )
    with pytest.raises(VolumeError, match="s.nhdr as the volume"):
        load_volume(p)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("{nope", "not readable JSON"),
        ("[1, 2, 3]", "must be a JSON object"),
        ('{"spacing": [1, 0, 2]}', "three positive numbers"),
        ('{"spacing": "1,1,2"}', "three positive numbers"),
        ('{"shape": [4, 6, 8.5]}', "three positive numbers"),
        ('{"dtype": "uint12"}', "unknown voxel type"),
    ],
)
def test_bad_sidecar_is_named_in_the_error(tmp_path, text, match):
    p = tmp_path / "v_4x6x8_uint16.raw"
    A.astype("<u2").tofile(p)
    (tmp_path / "v_4x6x8_uint16.json").write_text(text)
    with pytest.raises(VolumeError, match=match) as ei:
        load_volume(p)
    assert "v_4x6x8_uint16.json" in str(ei.value)


def test_unknown_sidecar_keys_are_noted(tmp_path):
    p = tmp_path / "v_4x6x8_uint16.raw"
    A.astype("<u2").tofile(p)
    (tmp_path / "v_4x6x8_uint16.json").write_text('{"spacings": [1, 1, 2]}')
    vol = load_volume(p)
    assert any("spacings" in n and "known: spacing" in n for n in vol.notes)


def test_no_spacing_note_names_the_shape_the_option_and_the_sidecar(tmp_path):
    p = tmp_path / "foot_4x6x8_uint16.raw"
    A.astype("<u2").tofile(p)
    vol = load_volume(p)
    note = next(n for n in vol.notes if "no voxel spacing" in n)
    assert "4x6x8 voxels" in note
    assert "--spacing 0.5,0.5,1.0" in note
    assert "foot_4x6x8_uint16.json" in note and '{"spacing": [X, Y, Z]}' in note


def test_no_spacing_note_of_other_formats_names_the_option(tmp_path):
    p = tmp_path / "v.npy"
    np.save(p, A)
    note = next(n for n in load_volume(p).notes if "no voxel spacing" in n)
    assert "--spacing X,Y,Z" in note and "sidecar" not in note


def test_raw_without_shape_suggests_a_sidecar(tmp_path):
    p = tmp_path / "mystery.raw"
    p.write_bytes(bytes(64))
    with pytest.raises(VolumeError, match="mystery.json"):
        load_volume(p)

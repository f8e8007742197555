"""Agreement score, JSONL labels and the judge-agreement command."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from intuitf.cli.app import main
from intuitf.evaluator.agreement import LabelError, agreement_score, parse_pairs
from intuitf.testing.fake_mllm import FakeMLLMServer, TargetOracle


def test_agreement_score_formula():
    assert agreement_score([1, 0, 1], [1, 0, 1]) == 1.0
    assert agreement_score([1, 0], [0, 1]) == 0.0
    assert agreement_score([0.5, 0.5], [1, 0]) == 0.5
    assert agreement_score([0.8], [0.5]) == pytest.approx(0.5)
    assert agreement_score([0.9, 0.2], [1.0, 0.0]) == pytest.approx((0.9 + 0.8) / 2)


def test_parse_pairs_labels_and_errors():
    pairs = parse_pairs(
        [
            '{"first": "a.png", "second": "b.png", "human": "first"}',
            "",
            "# a comment",
            '{"first": "a.png", "second": "c.png", "human": "Tie", "aspect": "text_alignment"}',
            '{"first": "a.png", "second": "d.png", "p_first": 0.25, "text": "red bone"}',
        ]
    )
    assert [p.q for p in pairs] == [1.0, 0.5, 0.25]
    assert pairs[1].aspect == "text_alignment" and pairs[2].text == "red bone"
    assert [p.line for p in pairs] == [1, 4, 5]
    with pytest.raises(LabelError, match="line 2"):
        parse_pairs(['{"first": "a", "second": "b", "human": "first"}', '{"first": "a", '])
    with pytest.raises(LabelError, match="line 1.*human"):
        parse_pairs(['{"first": "a", "second": "b", "human": "left"}'])
    with pytest.raises(LabelError, match="p_first"):
        parse_pairs(['{"first": "a", "second": "b", "p_first": 1.5}'])
    with pytest.raises(LabelError, match="second"):
        parse_pairs(['{"first": "a", "human": "tie"}'])


def _write_dataset(tmp_path, flip: int = 0):
    """Blends of a target with noise; labels from the oracle (the first ``flip`` inverted)."""
    rng = np.random.default_rng(0)
    target = (rng.random((32, 32, 3)) * 255).astype(np.uint8)
    (tmp_path / "img").mkdir()
    names = []
    for i, w in enumerate(np.linspace(0.1, 0.9, 6)):
        noise = (rng.random((32, 32, 3)) * 255).astype(np.float32)
        img = (w * target + (1 - w) * noise).astype(np.uint8)
        Image.fromarray(img).save(tmp_path / "img" / f"c{i}.png")
        names.append((f"img/c{i}.png", img))
    oracle = TargetOracle(target)
    lines = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            better = oracle(names[i][1]) > oracle(names[j][1])
            if len(lines) < flip:
                better = not better
            lines.append(
                json.dumps(
                    {
                        "first": names[i][0],
                        "second": names[j][0],
                        "human": "first" if better else "second",
                    }
                )
            )
    path = tmp_path / "pairs.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return target, path, len(lines)


def test_cli_agreement_with_fake_model_is_perfect_on_its_own_oracle(tmp_path, capsys):
    target, path, n = _write_dataset(tmp_path, flip=3)
    with FakeMLLMServer(target=target) as server:
        main(["judge-agreement", str(path), "--evaluator", f"{server.base_url}#default"])
        assert server.stats.answered == 2 * n  # swap "always": both orders per pair
    out = capsys.readouterr().out
    expected = (n - 3) / n
    assert f"{expected:.3f}" in out and str(n) in out


def test_cli_metric_judge_runs_offline(tmp_path, capsys):
    _, path, n = _write_dataset(tmp_path)
    main(["judge-agreement", str(path), "--evaluator", "metric"])
    out = capsys.readouterr().out
    assert "metric" in out and "overall" in out


def test_cli_bad_line_is_one_clear_error(tmp_path, capsys):
    path = tmp_path / "pairs.jsonl"
    path.write_text('{"first": "a.png", "second": "b.png", "human": "first"}\n{oops\n')
    with pytest.raises(SystemExit) as info:
        main(["judge-agreement", str(path)])
    assert info.value.code == 2
    err = " ".join(capsys.readouterr().err.split())  # Rich wraps long lines
    assert "line 2 is not valid JSON" in err and "Traceback" not in err
    path.write_text('{"first": "missing.png", "second": "b.png", "human": "first"}\n')
    with pytest.raises(SystemExit):
        main(["judge-agreement", str(path)])
    assert "missing.png" in " ".join(capsys.readouterr().err.split())

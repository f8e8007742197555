"""Every RunSpec field is checked by the spec's own schema before anything is written, and one
error names every bad field in the words of the API."""

from __future__ import annotations

import pytest

from intuitf.session import Session
from intuitf.session.settings import RunSettings
from intuitf.session.spec import SettingsSchema, SpecError, parse_spec

BAD = [
    ({"settings": {"population": "eight"}}, "settings.population"),
    ({"settings": {"population": 8.5}}, "settings.population"),
    ({"settings": {"population": 2}}, "settings.population"),
    ({"settings": {"output_size": "big"}}, "settings.output_size"),
    ({"settings": {"seed": "abc"}}, "settings.seed"),
    ({"settings": {"seed": -1}}, "settings.seed"),
    ({"settings": {"explorer": "sgd"}}, "settings.explorer"),
    ({"settings": {"protocol": "fast"}}, "settings.protocol"),
    ({"settings": {"stages": [["warmup", 2]]}}, "settings.stages.0.0"),
    ({"settings": {"stages": [["customize", -2]]}}, "settings.stages.0.1"),
    ({"settings": {"init_share": 5}}, "settings.init_share"),
    ({"settings": {"background": [255, 0, 0]}}, "settings.background.0"),
    ({"settings": {"shading": "maybe"}}, "settings.shading"),
    ({"settings": {"device": "tpu"}}, "settings.device"),
    ({"settings": {"camera": {"zoom": -1}}}, "settings.camera"),
    ({"settings": {"bogus": 1}}, "settings.bogus"),
    (
        {"judge": {"spec": "http://127.0.0.1:9/v1", "options": {"bogus": 1}}},
        "judge.options.bogus",
    ),  # fmt: skip
    (
        {"judge": {"spec": "http://127.0.0.1:9/v1", "options": {"timeout": 0}}},
        "judge.options.timeout",
    ),  # fmt: skip
    ({"judge": {"spec": "metric", "budget_calls": -3}}, "judge.budget_calls"),
]


@pytest.mark.parametrize(("change", "field"), BAD, ids=[f for _, f in BAD])
def test_a_bad_field_is_named_and_nothing_is_written(change, field, tmp_path):
    spec = {"volume": "phantom", **change}
    with pytest.raises(SpecError) as info:
        parse_spec(spec)
    assert field in info.value.fields, info.value.fields
    assert field in info.value.message
    run = tmp_path / "run"
    with pytest.raises(SpecError):
        Session.open(spec, run)
    assert not run.exists()  # no run.json, no .lock: nothing to clean up


def test_one_error_names_every_bad_field():
    with pytest.raises(SpecError) as info:
        parse_spec({"volume": "phantom", "intent": {"kind": "text"},
                    "settings": {"population": 8.5, "seed": -1, "protocol": "fast",
                                 "background": [255, 0, 0]}})  # fmt: skip
    assert set(info.value.fields) == {
        "intent", "settings.population", "settings.seed", "settings.protocol",
        "settings.background.0",
    }  # fmt: skip


def test_good_values_are_normalised_and_stored_as_used():
    spec = parse_spec({"volume": "phantom", "settings": {"population": "8", "seed": 7.0,
                                                        "background": [1, 0, 0]}})  # fmt: skip
    assert spec.settings == {"population": 8, "seed": 7, "background": [1.0, 0.0, 0.0]}
    assert spec.run_settings().population == 8


def test_the_schema_covers_every_setting():
    assert set(SettingsSchema.model_fields) == RunSettings.field_names()

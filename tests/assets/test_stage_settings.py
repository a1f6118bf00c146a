"""The per-stage Dagster settings mirror the library's dataclasses: same fields, defaults and descriptions."""

import dataclasses

import dagster as dg
import pytest

from assets.settings import ExtrinsicsSettings, IntrinsicsSettings, attribute_docs
from humancal.calibration import ExtrinsicsConfig, IntrinsicsConfig

PAIRS = [(IntrinsicsSettings, IntrinsicsConfig), (ExtrinsicsSettings, ExtrinsicsConfig)]


@pytest.mark.parametrize("settings, library", PAIRS, ids=lambda c: c.__name__)
def test_settings_mirror_their_dataclass(settings, library):
    fields = {f.name: f for f in dataclasses.fields(library)}
    assert list(settings.model_fields) == list(fields), "same fields in the same order"
    docs = attribute_docs(library)
    for name, field in settings.model_fields.items():
        expected = settings.PIPELINE_DEFAULTS.get(name, fields[name].default)
        default = tuple(field.default) if isinstance(fields[name].default, tuple) else field.default
        assert default == expected, name
        assert field.description and field.description == docs[name], name
    assert settings().to_library() == library(**settings.PIPELINE_DEFAULTS)


def test_the_pipeline_defers_views_without_upright_people():
    assert IntrinsicsSettings.PIPELINE_DEFAULTS == {"missing_upright": "defer"}
    assert IntrinsicsSettings().to_library().missing_upright == "defer"


def test_to_library_converts_and_validates():
    config = ExtrinsicsSettings(focal_range_rel=[0.2, 4.0], person_scale_std=None).to_library()
    assert config.focal_range_rel == (0.2, 4.0) and config.person_scale_std is None
    with pytest.raises(ValueError, match="ExtrinsicsConfig.max_groups must be an integer >= 3, got 2"):
        ExtrinsicsSettings(max_groups=2).to_library()


def test_docstring_entries_naming_two_attributes_and_continuations():
    docs = attribute_docs(IntrinsicsConfig)
    assert docs["plumb_top"] == docs["plumb_bottom"] and docs["plumb_top"].endswith("ankles, heels and toes).")
    assert docs["lean_std_deg"].endswith("and sets the uncertainty).")


def test_the_calibration_assets_take_their_settings_as_run_config():
    from pipelines.definitions import build_definitions

    defs = build_definitions("/nonexistent")
    job = defs.resolve_implicit_global_asset_job_def()
    schema = job.run_config_schema.config_type.fields["ops"].config_type.fields
    assert "shape_std_m" in schema["extrinsics"].config_type.fields["config"].config_type.fields
    assert "missing_upright" in schema["intrinsics"].config_type.fields["config"].config_type.fields
    assert isinstance(defs.resources["torch_runtime"], dg.ConfigurableResource)

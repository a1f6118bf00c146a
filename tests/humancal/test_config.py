"""The configuration base: ranges declared on fields, validated copies, digests; every stage's settings use it."""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
from dataclasses import dataclass, field

import numpy as np
import pytest

import humancal
from humancal.config import Config, Range, at_least, in_range, positive

USER_INPUT_CONFIGS = {"CaptureConfig"}
"""Dataclasses named ``*Config`` that describe a user's input rather than a stage's settings: their messages name
the capture file's fields (``fps: expected a positive number``), not a class."""


@dataclass(frozen=True)
class ToyConfig(Config):
    scale_m: float = field(default=0.3, metadata=positive())
    share: float = field(default=0.5, metadata=in_range(0, 1, high_open=True))
    views: int = field(default=2, metadata=at_least(2, integer=True))
    people: int | None = field(default=None, metadata=at_least(1, integer=True, optional=True))
    name: str = "toy"


@pytest.mark.parametrize("change, message", [
    ({"scale_m": 0.0}, "ToyConfig.scale_m must be a positive number, got 0.0"),
    ({"scale_m": float("nan")}, "ToyConfig.scale_m must be a positive number, got nan"),
    ({"share": 1.0}, r"ToyConfig.share must be a number in \[0, 1\), got 1.0"),
    ({"views": 2.0}, "ToyConfig.views must be an integer >= 2, got 2.0"),
    ({"views": True}, "ToyConfig.views must be an integer >= 2, got True"),
    ({"people": 0}, "ToyConfig.people must be None or an integer >= 1, got 0"),
])
def test_a_value_out_of_its_declared_range_is_refused_naming_class_field_range_and_value(change, message):
    with pytest.raises(ValueError, match=f"^{message}$"):
        ToyConfig(**change)
    with pytest.raises(ValueError, match=f"^{message}$"):
        ToyConfig().replace(**change)


def test_values_in_range_are_kept_as_given():
    config = ToyConfig(scale_m=np.float32(2.5), share=0, views=np.int64(5), people=3)
    assert (config.scale_m, config.share, config.views, config.people) == (2.5, 0, 5, 3)


def test_replace_refuses_unknown_fields_and_digest_names_the_values():
    config = ToyConfig()
    with pytest.raises(ValueError, match=r"^ToyConfig has no field\(s\) \['scales'\]; fields are \['name', 'people', 'scale_m', 'share', 'views'\]$"):
        config.replace(scales=1.0)
    assert config.replace(name="toy").digest() == config.digest() == ToyConfig().digest()
    assert config.replace(scale_m=0.31).digest() != config.digest()
    assert config.to_dict() == {"scale_m": 0.3, "share": 0.5, "views": 2, "people": None, "name": "toy"}


def test_ranges_describe_themselves():
    assert Range(0, 90, low_open=True, high_open=True).describe() == "a number in (0, 90)"
    assert Range(1e-7, 1.0).describe() == "a number in [1e-07, 1]"
    assert Range(0, 2**63 - 1, integer=True).describe() == "an integer in [0, 9223372036854775807]"
    assert Range(high=5).describe() == "a number <= 5" and Range().describe() == "a finite number"
    assert Range(0, low_open=True, integer=True).admits(1) and not Range(0, low_open=True).admits(float("inf"))


def _config_classes() -> list[type]:
    found = {}
    for info in pkgutil.walk_packages(humancal.__path__, "humancal."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if (inspect.isclass(value) and value.__module__ == info.name and name.endswith("Config")
                    and dataclasses.is_dataclass(value)):
                found[name] = value
    return sorted(found.values(), key=lambda cls: cls.__name__)


def test_every_settings_dataclass_of_the_library_derives_from_the_base():
    classes = _config_classes()
    assert len(classes) >= 16
    outside = [cls.__name__ for cls in classes if not issubclass(cls, Config) and cls.__name__ not in USER_INPUT_CONFIGS]
    assert outside == []
    for cls in classes:
        if issubclass(cls, Config):
            for method in ("replace", "digest", "check_ranges"):
                assert getattr(cls, method) is getattr(Config, method), (cls.__name__, method)

"""The code location as Dagster users open it: ``workspace.yaml`` at the top level names the module that
``pyproject.toml`` names, and ``dagster definitions validate -w workspace.yaml`` loads it."""

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]


def test_the_workspace_names_the_definitions_module():
    workspace = yaml.safe_load((REPO / "workspace.yaml").read_text())
    (location,) = workspace["load_from"]
    module = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["dagster"]["module_name"]
    assert location["python_module"]["module_name"] == module == "pipelines.definitions"


@pytest.mark.slow
def test_dagster_loads_the_workspace(tmp_path):
    env = dict(os.environ, DAGSTER_HOME=str(tmp_path), HUMANCAL_STATE_DIR=str(tmp_path))
    done = subprocess.run([sys.executable, "-m", "dagster", "definitions", "validate", "-w", "workspace.yaml"],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "All code locations passed validation" in done.stderr + done.stdout

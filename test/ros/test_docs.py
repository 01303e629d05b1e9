"""The README documents every declared parameter of the nodes, with its default."""

from __future__ import annotations

from pathlib import Path

import pytest

from switchobs_ros import camera_sim, estimator

DOC = Path(__file__).resolve().parents[2] / "README.md"


@pytest.mark.parametrize("mod", [estimator, camera_sim])
def test_every_parameter_documented(mod):
    text = DOC.read_text()
    missing = [p.name for p in mod.PARAMS if f"| `{p.name}` |" not in text]
    assert not missing, f"parameters missing from README.md: {missing}"


@pytest.mark.parametrize("mod,cfg", [(estimator, "estimator.yaml"), (camera_sim, "camera_sim.yaml")])
def test_default_params_file_lists_every_parameter(mod, cfg):
    import yaml

    node = "estimator" if mod is estimator else "camera_sim"
    data = yaml.safe_load((DOC.parent / "config" / cfg).read_text())[node]["ros__parameters"]

    def flat(d, prefix=""):
        for k, v in d.items():
            if isinstance(v, dict):
                yield from flat(v, f"{prefix}{k}.")
            else:
                yield f"{prefix}{k}"
    assert set(flat(data)) == {p.name for p in mod.PARAMS}

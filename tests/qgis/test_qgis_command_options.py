"""The QGIS tools pass every option parameter they show to the engine: each set to a value
other than its default reaches the command line as its flag with that value."""

from __future__ import annotations

from dataclasses import fields

import pytest
from qgis.core import QgsApplication

from soilvolume.options import Options, command_fields

TOOLS = {"registerpointclouds": "register", "pointcloudtodem": "dem", "stockpilevolumes": "stockpile"}


class Captured(Exception):
    pass


def other_value(field):
    """A value of ``field`` inside its range and different from its default."""
    meta, default = field.metadata, field.default
    if field.name.endswith("_crs"):
        return "EPSG:32654"
    if field.name == "base":
        return "plane"
    if meta["choices"]:
        return next(c for c in meta["choices"] if c != default)
    lo, hi = meta["lo"], meta["hi"]
    if str(field.type).startswith("int"):
        return int(min(hi, max(lo, (default or 0) + 1)))
    value = 1.7 if not default else default * 0.7
    return float(min(hi, max(lo + 1e-3, value)))


@pytest.mark.parametrize("tool", sorted(TOOLS))
def test_every_option_shown_reaches_the_engine(tool, provider, scene_dir, monkeypatch, tmp_path):
    from qgis import processing
    from soilvolume_qgis.processing import engine

    alg = QgsApplication.processingRegistry().algorithmById(f"soilvolume:{tool}")
    names = {f.name.upper(): f for f in fields(Options)}
    shown = [names[p.name()] for p in alg.parameterDefinitions() if p.name() in names]
    assert {f.name for f in shown} == {f.name for f in command_fields(TOOLS[tool])} - {"keep_registered_cloud"}
    given = {f.name.upper(): other_value(f) for f in shown}
    cloud = str(scene_dir / "before.las")
    inputs = (
        {"BEFORE": cloud, "AFTER": str(scene_dir / "after.las")} if tool.startswith("register") else {"INPUT": cloud}
    )
    seen = []

    def run(args, feedback, hint=""):
        seen.append(list(args))
        raise Captured

    monkeypatch.setattr(engine, "run", run)
    with pytest.raises(Exception):  # noqa: B017 (processing.run wraps what the algorithm raised)
        processing.run(f"soilvolume:{tool}", {**inputs, **given, "OUTPUT": str(tmp_path / "out.laz")})
    (args,) = seen
    for field in shown:
        flag = "--" + field.name.replace("_", "-")
        assert flag in args, (tool, flag, args)
        value = args[args.index(flag) + 1]
        want = given[field.name.upper()]
        if isinstance(want, float):
            assert float(value) == pytest.approx(want), (flag, value)
        else:
            assert value == str(want), (flag, value)

"""Presets, TOML overrides with validation, and the resolved-config round trip."""

from __future__ import annotations

import pickle
from pathlib import Path

import pytest

from gndreplay.config import PRESETS, Config, config_to_toml, load_config, preset
from gndreplay.errors import ConfigError


def test_presets_match_the_papers() -> None:
    wc = PRESETS["wheelchair"]
    assert (wc.robot.shape, wc.robot.drive) == ("rectangle", "differential")
    assert wc.robot.front_m + wc.robot.rear_m == pytest.approx(1.2) and wc.robot.width_m == 0.7
    assert (wc.robot.laser_x_m, wc.robot.vmax_mps, wc.robot.wmax_radps) == (0.72, 0.3, 0.5)
    assert (wc.grid.size_cells, wc.grid.cell_m) == (400, 0.05)
    sup = wc.supervisor
    assert (sup.budget_model_s, sup.budget_planner_s, sup.budget_reactor_s) == (0.05, 0.08, 0.02)
    xr = PRESETS["xr4000"]
    assert (xr.robot.shape, xr.robot.drive, xr.robot.radius_m) == ("circle", "holonomic", 0.3)
    assert (xr.robot.vmax_mps, xr.robot.wmax_radps) == (0.5, 1.57)
    assert (xr.grid.size_cells, xr.grid.cell_m) == (200, 0.05)


def test_unknown_preset() -> None:
    with pytest.raises(ConfigError, match="unknown preset 'tank'; known: wheelchair, xr4000"):
        preset("tank")


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "cfg.toml"
    p.write_text(text)
    return p


def test_overrides_apply_and_keep_the_rest(tmp_path: Path) -> None:
    text = "[robot]\nvmax_mps = 0.2\n[grid]\nsize_cells = 200\n[scanmatch]\nmethod = 'odom'\n"
    cfg = load_config(write(tmp_path, text))
    assert cfg.robot.vmax_mps == 0.2 and cfg.robot.wmax_radps == 0.5
    assert cfg.grid.size_cells == 200 and cfg.grid.cell_m == 0.05
    assert cfg.scanmatch.method == "odom"


def test_int_is_accepted_for_a_float(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[robot]\nvmax_mps = 1\n"))
    assert cfg.robot.vmax_mps == 1.0 and isinstance(cfg.robot.vmax_mps, float)


def test_preset_from_file_and_from_option(tmp_path: Path) -> None:
    assert load_config(write(tmp_path, 'preset = "xr4000"\n')).robot.shape == "circle"
    assert load_config(None, preset_name="xr4000").preset == "xr4000"
    with pytest.raises(ConfigError, match="conflicts with --preset wheelchair"):
        load_config(write(tmp_path, 'preset = "xr4000"\n'), preset_name="wheelchair")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[robot]\nvmaxx = 0.2\n", r"cfg.toml: unknown key 'robot.vmaxx' \(known in \[robot\]: "),
        ("[robto]\nvmax_mps = 0.2\n", r"unknown key 'robto'"),
        ("[robot]\nvmax_mps = 'fast'\n", r"robot.vmax_mps: expected a number, got 'fast'"),
        ("[grid]\nsize_cells = 2.5\n", r"grid.size_cells: expected an integer, got 2.5"),
        ("[cspace]\nunknown_is_free = 1\n", r"cspace.unknown_is_free: expected true or false, got 1"),
        ("[robot]\nshape = 'oval'\n", r"robot.shape: expected one of 'circle', 'rectangle', got 'oval'"),
        ("[planner]\nconnectivity = 6\n", r"planner.connectivity: expected one of 4, 8, got 6"),
        ("robot = 3\n", r"robot: expected a table"),
        ("[grid]\ncell_m = -1.0\n", r"cell_m must be > 0"),
        ("[scanmatch.idc]\nnot_a_key = 1\n", r"unknown key 'scanmatch.idc.not_a_key'"),
        ("[robot\n", r"cfg.toml: not a valid TOML file"),
    ],
)
def test_bad_config_names_the_file_and_key(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_config(write(tmp_path, text))


def test_missing_config_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "nope.toml")


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_resolved_config_round_trips_through_toml(tmp_path: Path, name: str) -> None:
    cfg = load_config(write(tmp_path, "[robot]\nvmax_mps = 0.25\n"), preset_name=name)
    again = load_config(write(tmp_path, config_to_toml(cfg)))
    assert again == cfg


def test_config_pickles_for_batch_workers() -> None:
    cfg = PRESETS["xr4000"]
    assert pickle.loads(pickle.dumps(cfg)) == cfg
    assert isinstance(cfg, Config)

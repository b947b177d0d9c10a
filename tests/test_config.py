"""Presets, TOML overrides with validation, and the resolved-config round trip."""

from __future__ import annotations

import dataclasses
import math
import pickle
import typing
from pathlib import Path

import pytest

from gndreplay.config import (
    CROSS_CHECKS,
    PRESETS,
    RANGES,
    Config,
    Range,
    config_to_toml,
    load_config,
    numeric_fields,
    preset,
    range_of,
    validate_config,
)
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
    assert (xr.grid.size_cells, xr.grid.cell_m) == (400, 0.05)


def test_unknown_preset() -> None:
    with pytest.raises(ConfigError, match="unknown preset 'tank'; known: compact, wheelchair, xr4000"):
        preset("tank")


def test_presets_are_case_insensitive(tmp_path: Path) -> None:
    assert preset("XR4000") is PRESETS["xr4000"] and preset("Wheelchair") is PRESETS["wheelchair"]
    assert load_config(None, preset_name="XR4000").preset == "xr4000"
    # the file's preset and --preset agree whatever their case
    cfg = load_config(write(tmp_path, 'preset = "Xr4000"\n'), preset_name="XR4000")
    assert cfg.preset == "xr4000" and cfg.robot.shape == "circle"


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


def test_planner_section_shared_settings_and_one_table_per_planner(tmp_path: Path) -> None:
    text = "[planner]\nkind = 'tunnel'\nlookahead_m = 0.8\n[planner.nf1]\nconnectivity = 8\n"
    cfg = load_config(write(tmp_path, text + "[planner.tunnel]\nn_rays = 720\n"))
    p = cfg.planner
    assert (p.kind, p.lookahead_m, p.nf1.connectivity, p.tunnel.n_rays) == ("tunnel", 0.8, 8, 720)
    assert cfg.stack_params().planner is p
    d = PRESETS["wheelchair"].planner  # the defaults
    assert (d.kind, d.lookahead_m, d.route_keep_ratio, d.route_keep_m) == ("nf1", 1.0, 0.1, 0.3)
    assert dataclasses.astuple(d.nf1) == (4, 0.5, True, 1.0, True, 1.0)


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
        ("[robot]\nvmaxx = 0.2\n",
         r"cfg.toml: unknown key 'robot.vmaxx' \(did you mean 'vmax_mps'\?\) \(known in \[robot\]: "),
        ("[robto]\nvmax_mps = 0.2\n", r"unknown key 'robto'"),
        ("[robot]\nvmax_mps = 'fast'\n", r"robot.vmax_mps: expected a number, got 'fast'"),
        ("[grid]\nsize_cells = 2.5\n", r"grid.size_cells: expected an integer, got 2.5"),
        ("[cspace]\nunknown_is_free = 1\n", r"cspace.unknown_is_free: expected true or false, got 1"),
        ("[robot]\nshape = 'oval'\n", r"robot.shape: expected one of 'circle', 'rectangle', got 'oval'"),
        ("[planner.nf1]\nconnectivity = 6\n", r"planner.nf1.connectivity: expected one of 4, 8, got 6"),
        # NF1's own settings are in its table, not in [planner]
        ("[planner]\nconnectivity = 8\n",
         r"cfg.toml: unknown key 'planner.connectivity' \(a key of \[planner.nf1\]\) \(known in "),
        ("[planner]\nkind = 'rrt'\n", r"\[planner\] kind: expected one of nf1, tunnel, got 'rrt'"),
        ("robot = 3\n", r"robot: expected a table"),
        ("[grid]\ncell_m = -1.0\n", r"cfg.toml: grid.cell_m must be in \[0.001, 10\], got -1.0"),
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


# ---------------------------------------------------------------- physical ranges


def _sections(cls: type) -> list[type]:
    """Every section dataclass reachable from ``cls`` (itself included)."""
    out = [cls]
    for tp in typing.get_type_hints(cls).values():
        if dataclasses.is_dataclass(tp) and isinstance(tp, type):
            out += _sections(tp)
    return out


def test_every_numeric_field_of_every_section_has_a_range() -> None:
    missing = [
        f"{cls.__name__}.{name}" for cls in _sections(Config) for name in numeric_fields(cls)
        if range_of(cls, name) is None
    ]
    assert not missing, f"add these to config.RANGES: {missing}"
    # and the table names no field that does not exist (a renamed field would leave a dead entry);
    # a section may inherit its fields' ranges from a base section (PlannerParams from RouteParams)
    known = {
        (base, name) for cls in _sections(Config) for base in cls.__mro__ for name in numeric_fields(cls)
    }
    assert set(RANGES) <= known
    assert all(math.isfinite(r.lo) and math.isfinite(r.hi) and r.lo < r.hi for r in RANGES.values())


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_are_in_range(name: str) -> None:
    assert validate_config(PRESETS[name]) is PRESETS[name]


def test_range_ends_and_text() -> None:
    r = Range(0.0, 10.0, lo_open=True)
    assert 0.0 not in r and 1e-9 in r and 10.0 in r and 10.0001 not in r
    assert math.nan not in r and math.inf not in r
    assert str(r) == "(0, 10]" and str(Range(-1.0, 1.0, hi_open=True)) == "[-1, 1)"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[robot]\nvmax_mps = -1\n", r"cfg.toml: robot.vmax_mps must be in \(0, 10\], got -1.0"),
        ("[robot]\nwmax_radps = 0\n", r"cfg.toml: robot.wmax_radps must be in \(0, 20\], got 0.0"),
        ("[robot]\naccel_mps2 = nan\n", r"robot.accel_mps2 must be in \(0, 50\], got nan"),
        ("[robot]\nwidth_m = 0.0\n", r"robot.width_m must be in \(0, 10\]"),
        ("[laser]\nbeams = 0\n", r"laser.beams must be in \[2, 100000\], got 0"),
        ("[laser]\nnoise_std_m = -0.1\n", r"laser.noise_std_m must be in \[0, 10\]"),
        ("[laser]\nperiod_s = inf\n", r"laser.period_s must be in \(0, 60\], got inf"),
        ("[grid]\nsize_cells = 100000\n", r"grid.size_cells must be in \[4, 4000\], got 100000"),
        ("[supervisor]\nbudget_planner_s = -0.08\n", r"supervisor.budget_planner_s must be in \(0, 60\]"),
        ("[supervisor]\nrotate_w_frac = 1.5\n", r"supervisor.rotate_w_frac must be in \(0, 1\]"),
        ("[supervisor]\ntrap_window = 0\n", r"supervisor.trap_window must be in \[1, 1000000\]"),
        ("[scanmatch.idc]\nmin_pair_fraction = 2\n", r"scanmatch.idc.min_pair_fraction must be in \[0, 1\]"),
        ("[scanmatch.kiss]\nfixed_threshold_m = -1\n", r"scanmatch.kiss.fixed_threshold_m must be in"),
        ("[reactor]\ngap_m = 0.0\n", r"reactor.gap_m"),
        # cross-field constraints
        ("[robot]\nfront_m = 0.0\nrear_m = 0.0\n", r"cfg.toml: \[robot\] front_m, rear_m: a rectangle needs"),
        ("[scanmatch.idc]\nmin_range_m = 50.0\n", r"\[scanmatch.idc\] min_range_m, max_range_m"),
        ("[supervisor]\ntrap_count = 50\n", r"\[supervisor\] trap_count, trap_window"),
    ],
)
def test_out_of_range_values_name_the_file_and_key(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_config(write(tmp_path, text))


def test_edges_of_the_ranges_are_accepted(tmp_path: Path) -> None:
    text = "[robot]\nvmax_mps = 10\nlaser_theta_rad = -3.14\n[laser]\nnoise_std_m = 0\n[scanmatch.idc]\n"
    cfg = load_config(write(tmp_path, text + "polish_iterations = 0\nfallback_priors = 0\n"))
    assert (cfg.robot.vmax_mps, cfg.laser.noise_std_m, cfg.scanmatch.idc.polish_iterations) == (10.0, 0.0, 0)
    # a circle ignores the rectangle's front / rear
    circle = load_config(write(tmp_path, "[robot]\nshape = 'circle'\nfront_m = 0.0\nrear_m = 0.0\n"))
    assert circle.robot.shape == "circle"


def test_cross_checks_refer_to_sections_of_the_config() -> None:
    sections = set(_sections(Config))
    assert all(cls in sections for cls, *_ in CROSS_CHECKS)
    # every preset satisfies every cross-field constraint, checked on the section itself
    for cfg in PRESETS.values():
        for cls, _, holds, _ in CROSS_CHECKS:
            found = [s for s in (cfg.robot, cfg.scanmatch.idc, cfg.scanmatch.kiss, cfg.supervisor)
                     if type(s) is cls]
            assert len(found) == 1 and holds(found[0])

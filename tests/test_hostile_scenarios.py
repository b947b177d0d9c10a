"""Hostile scenario files: each is refused in one line naming the file and the key, at once and in bounded
memory (special files, size, nesting, alias bombs, merge keys, list lengths, numbers beyond their physical
range), and the simulator refuses a seed or a time limit its clock cannot hold."""

from __future__ import annotations

import math
import os
import resource
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from gndreplay.config import preset
from gndreplay.errors import ConfigError
from gndreplay.sim import ClosedLoop
from gndreplay.sim.scenario_file import (
    MAX_ELEMENTS,
    MAX_EVENTS,
    MAX_ID_CHARS,
    MAX_MOVERS,
    MAX_POINTS,
    MAX_SCENARIO_BYTES,
    MAX_TELEOP_ROWS,
    load_scenario,
    parse_scenario,
    resolve_scenario,
)

BASE_YAML = "name: x\nstart: [0, 0, 0]\ngoal: [1, 1]\ntime_limit: 5\nworld: {walls: {w: [0, 2, 1, 2]}}\n"
BIG = 10**400  # float() of it overflows
MOVER = {"id": "p", "radius": 0.2, "speed": 1.0, "path": [[0, 5], [1, 5]]}


def doc(**keys: Any) -> dict[str, Any]:
    base: dict[str, Any] = {"name": "x", "start": [0, 0, 0], "goal": [1, 1], "time_limit": 5,
                            "world": {"walls": {"w": [0, 2, 1, 2]}}}
    base.update(keys)
    return base


def refused(d: Any, *needles: str) -> str:
    """The one-line, short error of parsing ``d`` as ``h.yaml``, holding every needle."""
    with pytest.raises(ConfigError) as e:
        parse_scenario(d, "h.yaml")
    return one_line(str(e.value), "h.yaml: ", *needles)


def one_line(msg: str, start: str, *needles: str) -> str:
    assert msg.startswith(start) and "\n" not in msg and len(msg) < 400, msg[:1000]
    assert all(n in msg for n in needles), msg
    return msg


def write(tmp_path: Path, text: str, name: str = "h.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def cli(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    """``gndreplay`` in a child process with 2 GB of address space and a time limit: a regression (a read
    that never ends, a message the size of a billion-laughs document) fails the test, not the machine."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))

    return subprocess.run([sys.executable, "-c", "from gndreplay.cli import main; main()", *args],
                          capture_output=True, text=True, timeout=timeout, preexec_fn=limit, check=False)


def cli_refuses(res: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert res.returncode == 2, res.stderr[-2000:]
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr[-2000:]
    one_line(lines[0], "gndreplay: error: ", *needles)


def laughs(levels: int) -> str:
    """A YAML flow list whose last item expands to 9**levels strings (each level an alias of the last)."""
    items = ["&l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    items += [f"&l{k} [{', '.join([f'*l{k - 1}'] * 9)}]" for k in range(1, levels)]
    return f"[{', '.join(items)}]"


# --------------------------------------------------------------------------------------------- reading


def test_a_fifo_scenario_is_refused_without_opening_it(tmp_path: Path) -> None:
    fifo = tmp_path / "x.yaml"
    os.mkfifo(fifo)
    cli_refuses(cli("simulate", str(fifo), "--out", str(tmp_path / "run"), timeout=60), "x.yaml: is a FIFO")
    assert not (tmp_path / "run").exists()


def test_a_scenario_linked_to_dev_zero_is_refused(tmp_path: Path) -> None:
    (tmp_path / "z.yaml").symlink_to("/dev/zero")
    cli_refuses(cli("simulate", str(tmp_path / "z.yaml"), timeout=60), "z.yaml: is a character device")


def test_a_billion_laughs_scenario_is_refused_in_bounded_memory(tmp_path: Path) -> None:
    f = write(tmp_path, BASE_YAML.replace("start: [0, 0, 0]", f"start: {laughs(10)}"))
    cli_refuses(cli("simulate", str(f), timeout=60), "h.yaml: more than 1,000,000 values")


def test_a_scenario_file_has_a_size_bound(tmp_path: Path) -> None:
    f = write(tmp_path, BASE_YAML + "#" * MAX_SCENARIO_BYTES + "\n")
    with pytest.raises(ConfigError) as e:
        load_scenario(f)
    one_line(str(e.value), str(f), "more than the 1 MB a scenario file may have")


@pytest.mark.parametrize(("text", "needle"), [
    (BASE_YAML.replace("start: [0, 0, 0]", "start: " + "[" * 5000 + "]" * 5000), "nested more than 64"),
    (BASE_YAML.replace("time_limit: 5", "time_limit: " + "1" * 5000), "an integer of 5000 characters"),
    (BASE_YAML.replace("time_limit: 5", "time_limit: 5" + ":1" * 20000), "an integer of 40001 characters"),
    (BASE_YAML.replace("time_limit: 5", "time_limit: 2024-13-01"), "not valid YAML: month must be in"),
    (BASE_YAML + "chain:\n  - &m0 {k0: 0}\n"
     + "".join(f"  - &m{i} {{<<: *m{i - 1}, k{i}: {i}}}\n" for i in range(1, 2000)),
     "merge keys (<<) copy more than 1,000,000 entries"),
])
def test_yaml_that_costs_more_than_its_size_is_one_line(tmp_path: Path, text: str, needle: str) -> None:
    """Deep nesting, a 5,000-digit integer, a base-60 integer of 20,000 parts (quadratic to build), an
    impossible date and a chain of merge keys (each mapping copying the previous one)."""
    with pytest.raises(ConfigError) as e:
        load_scenario(write(tmp_path, text))
    one_line(str(e.value), str(tmp_path / "h.yaml"), needle)


@pytest.mark.parametrize("where", ["start", "time_limit", "movers", "world"])
def test_an_alias_bomb_within_the_node_bound_is_quoted_short(tmp_path: Path, where: str) -> None:
    """9**6 strings (under the parser's bound on values) where a number, a list of movers or a wall goes:
    the error quotes a few of them, not half a million."""
    bomb = laughs(6)
    text = BASE_YAML.replace("time_limit: 5", f"time_limit: {bomb}") if where == "time_limit" else (
        BASE_YAML.replace("start: [0, 0, 0]", f"start: {bomb}") if where == "start" else
        BASE_YAML + f"movers: [{{id: p, radius: 0.2, speed: 1, path: [[0, 5]], loop: {bomb}}}]\n"
        if where == "movers" else
        BASE_YAML.replace("w: [0, 2, 1, 2]", f"w: {bomb}"))
    with pytest.raises(ConfigError) as e:
        load_scenario(write(tmp_path, text))
    key = {"start": "start", "time_limit": "time_limit", "movers": "movers[0].loop",
           "world": "world.walls.w"}[where]
    one_line(str(e.value), f"{tmp_path / 'h.yaml'}: {key}: ", "lol")


def test_a_shipped_scenario_is_a_plain_name(tmp_path: Path) -> None:
    assert resolve_scenario("u_trap").name == "u_trap"
    with pytest.raises(ConfigError, match=r"^\.\./scenarios/u_trap: no such scenario file or shipped"):
        resolve_scenario("../scenarios/u_trap")
    with pytest.raises(ConfigError, match=r"\(did you mean 'u_trap'\?\)$"):
        resolve_scenario("u_trp")


# --------------------------------------------------------------------------------------------- sizes


@pytest.mark.parametrize(("keys", "needle"), [
    ({"world": {"walls": {f"w{i}": [0, i, 1, i] for i in range(MAX_ELEMENTS + 1)}}},
     "world: more than the 10,000 elements"),
    ({"events": [{"at": 1, "add": {"circles": {f"c{i}": [0, i, 0.1] for i in range(MAX_ELEMENTS)}}}]},
     "events[0].add: more than the 10,000 elements"),
    ({"movers": [{**MOVER, "id": f"p{i}"} for i in range(MAX_MOVERS + 1)]}, "movers: 1,001 movers"),
    ({"events": [{"at": 1, "remove": "w"}] * (MAX_EVENTS + 1)}, "events: 10,001 events"),
    ({"world": {"polygons": {"p": [[i, 0] for i in range(MAX_POINTS + 1)]}}},
     "world.polygons.p: 10,001 [x, y] vertices"),
    ({"movers": [{**MOVER, "path": [[i, 5] for i in range(MAX_POINTS + 1)]}]},
     "movers[0].path: 10,001 [x, y] waypoints"),
    ({"mode": "teleop", "teleop": {"commands": [[i, 0, 0] for i in range(MAX_TELEOP_ROWS + 1)]}},
     "teleop.commands: 100,001 [t_s, v, w] rows"),
    ({"mode": "teleop", "teleop": {"track": {"points": [[i, 0] for i in range(MAX_POINTS + 1)],
                                             "speed": 1}}}, "teleop.track.points: 10,001 [x, y] points"),
    ({"mode": "follow", "subgoals": [[i, 0, 0] for i in range(MAX_POINTS + 1)]},
     "subgoals: 10,001 [x, y, theta, kind] rows"),
    ({"world": {"walls": {"w" * 5000: [0, 2, 1, 2]}}}, "world.walls: a name of 5,000 characters"),
    ({"movers": [{**MOVER, "id": "p" * (MAX_ID_CHARS + 1)}]}, "movers[0].id: a name of 101 characters"),
    ({"name": "n" * (MAX_ID_CHARS + 1)}, "name: expected a plain name"),
    ({"colour" * 1000: 1}, "h.yaml: 'colourcolour"),
])
def test_every_list_and_name_is_bounded(keys: dict[str, Any], needle: str) -> None:
    refused(doc(**keys), needle)


# --------------------------------------------------------------------------------------------- numbers


@pytest.mark.parametrize(("keys", "key"), [
    ({"goal": [BIG, 0]}, "goal[0]"),
    ({"start": [0, BIG, 0]}, "start[1]"),
    ({"time_limit": BIG}, "time_limit"),
    ({"world": {"walls": {"w": [0, 2, BIG, 2]}}}, "world.walls.w[2]"),
    ({"world": {"boxes": {"b": [0, 2, 1, 1, BIG]}}}, "world.boxes.b[4]"),
    ({"world": {"circles": {"c": [0, 2, BIG]}}}, "world.circles.c[2]"),
    ({"world": {"polygons": {"p": [[0, 0], [1, 0], [0, BIG]]}}}, "world.polygons.p[2][1]"),
    ({"movers": [{**MOVER, "speed": BIG}]}, "movers[0].speed"),
    ({"movers": [{**MOVER, "path": [[0, 0], [BIG, 0]]}]}, "movers[0].path[1][0]"),
    ({"events": [{"at": BIG, "remove": "w"}]}, "events[0].at"),
    ({"events": [{"at": 1, "close": "w", "over": BIG}]}, "events[0].over"),
    ({"mode": "teleop", "teleop": {"commands": [[0, BIG, 0], [1, 0, 0]]}}, "teleop.commands[0][1]"),
    ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [BIG, 0]], "speed": 1}}},
     "teleop.track.points[1][0]"),
    ({"mode": "teleop", "teleop": {"track": {"points": [[0, 0], [1, 0]], "speed": BIG}}},
     "teleop.track.speed"),
    ({"mode": "follow", "subgoals": [[1, 0, 0], [BIG, 0, 0]]}, "subgoals[1][0]"),
])
def test_a_401_digit_integer_is_refused_by_key(keys: dict[str, Any], key: str) -> None:
    refused(doc(**keys), f"h.yaml: {key}: ", "an integer of 401 digits")


@pytest.mark.parametrize(("keys", "key"), [
    ({"time_limit": 1e300}, "time_limit"),
    ({"time_limit": 1e6 + 1}, "time_limit"),
    ({"time_limit": 1e-12}, "time_limit"),  # no step shorter than the control period to take
    ({"events": [{"at": 1e300, "remove": "w"}]}, "events[0].at"),
    ({"events": [{"at": 1.0, "close": "w", "over": 1e300}]}, "events[0].over"),
    ({"events": [{"at": 1.0, "close": "w", "over": 1.0, "swing": 1e300}]}, "events[0].swing"),
    ({"movers": [{**MOVER, "start_at": 1e300}]}, "movers[0].start_at"),
    ({"movers": [{**MOVER, "speed": 1e300}]}, "movers[0].speed"),
    ({"movers": [{**MOVER, "radius": 1e300}]}, "movers[0].radius"),
    ({"movers": [{**MOVER, "yield_m": 1e300}]}, "movers[0].yield_m"),
    ({"world": {"walls": {"w": [0, 2, 1e300, 2]}}}, "world.walls.w[2]"),
    ({"world": {"walls": {"w": [0, 2, 1, 2, 1e300]}}}, "world.walls.w[4]"),
    ({"world": {"boxes": {"b": [0, 2, 1e300, 1, 0]}}}, "world.boxes.b[2]"),
    ({"world": {"boxes": {"b": [0, 2, 1, 1, 1e300]}}}, "world.boxes.b[4]"),
    ({"world": {"circles": {"c": [1e300, 2, 1]}}}, "world.circles.c[0]"),
])
def test_a_huge_number_is_refused_by_its_physical_range(keys: dict[str, Any], key: str) -> None:
    """Finite but absurd: 1e300 s would overflow the clock's nanoseconds, 1e300 m the geometry."""
    refused(doc(**keys), f"h.yaml: {key}: must be from ")


def test_the_bounds_themselves_are_accepted() -> None:
    mover = {**MOVER, "start_at": 1e6, "speed": 100}
    s = parse_scenario(doc(time_limit=1e6, goal=[1e6, -1e6], movers=[mover],
                           events=[{"at": 1e6, "close": "w", "over": 1e6, "swing": -360}]), "h.yaml")
    assert s.time_limit_s == 1e6 and s.goal == (1e6, -1e6) and s.elements[0].door[0].t1_s == 2e6
    assert parse_scenario(doc(time_limit=0.1), "h.yaml").time_limit_s == 0.1


def test_the_simulator_refuses_a_seed_or_time_limit_its_clock_cannot_hold() -> None:
    s = parse_scenario(doc(), "h.yaml")
    cfg = preset("wheelchair")
    for kw, needle in (({"seed": -1}, "seed: must be an integer from 0"),
                       ({"seed": 2**64}, "seed: must be an integer from 0"),
                       ({"seed": 0, "time_limit_s": math.inf}, "time limit [s]: must be finite"),
                       ({"seed": 0, "time_limit_s": 1e300}, "time limit [s]: must be from 0.1 to 1e+06"),
                       ({"seed": 0, "time_limit_s": 0.0}, "time limit [s]: must be from 0.1 to 1e+06"),
                       ({"seed": 0, "latency_s": math.inf}, "latency [s]: must be finite")):
        with pytest.raises(ConfigError) as e:
            ClosedLoop(s, cfg, **kw)
        one_line(str(e.value), needle)

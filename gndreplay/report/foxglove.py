"""A Foxglove layout (the JSON Foxglove imports under Layouts -> Import) for a results MCAP.

A layout is ``configById`` (one configuration per panel, keyed ``<PanelType>!<id>``), ``layout`` (the panel
tree: a panel id, or ``{"first", "second", "direction", "splitPercentage"}``), ``globalVariables``,
``userNodes``, ``linkedGlobalVariables`` and ``playbackConfig``. Panels used: a 3D panel following one frame,
Plot panels (message paths ``/topic.field.sub``), a State Transitions panel and Raw Messages panels. What to
show is the caller's ``LayoutSpec``; ``foxglove_layout`` keeps only what refers to the topics present.
"""

from __future__ import annotations

import json
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["LAYOUT_FILE", "LayoutSpec", "foxglove_layout", "layout_topics", "write_layout"]

LAYOUT_FILE = "results.foxglove.json"

Series = tuple[str, str]
"""A message path (``/topic.field``) and its label."""


@dataclass(frozen=True, slots=True)
class LayoutSpec:
    """What a layout shows.

    Attributes:
        frame: the 3D panel's display frame (the camera follows its pose).
        scene: topic -> the 3D panel's settings for it (``visible`` is set).
        plots: (title, series) per Plot panel.
        states: series of the State Transitions panel.
        raw: topics shown in a Raw Messages panel each.
        view_m: the 3D camera's distance [m] (top-down, orthographic).
    """

    frame: str
    scene: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    plots: Sequence[tuple[str, Sequence[Series]]] = ()
    states: Sequence[Series] = ()
    raw: Sequence[str] = ()
    view_m: float = 12.0


def _topic(path: str) -> str:
    """The topic of a message path (topic names hold no '.')."""
    return path.split(".", 1)[0]


def _series(series: Sequence[Series], present: Collection[str]) -> list[dict[str, Any]]:
    return [{"value": p, "label": label, "enabled": True, "timestampMethod": "receiveTime"}
            for p, label in series if _topic(p) in present]


def _split(panels: Sequence[str | dict[str, Any]], direction: str) -> str | dict[str, Any]:
    """Panels side by side (``direction`` "row") or stacked ("column"), in equal shares."""
    if len(panels) == 1:
        return panels[0]
    return {"first": panels[0], "second": _split(panels[1:], direction), "direction": direction,
            "splitPercentage": 100.0 / len(panels)}


def foxglove_layout(spec: LayoutSpec, topics: Collection[str]) -> dict[str, Any]:
    """The layout of ``spec`` restricted to ``topics`` (the channels of the file): a 3D panel on the left,
    the plots, the state transitions and the raw messages stacked on the right; a panel left with nothing
    to show is left out."""
    present = set(topics)
    config: dict[str, Any] = {"3D!scene": {
        "cameraState": {"perspective": False, "distance": spec.view_m, "phi": 0.0, "thetaOffset": 0.0,
                        "targetOffset": [0.0, 0.0, 0.0], "target": [0.0, 0.0, 0.0],
                        "targetOrientation": [0.0, 0.0, 0.0, 1.0], "fovy": 45, "near": 0.01, "far": 5000},
        "followMode": "follow-pose", "followTf": spec.frame,
        "scene": {"transforms": {"showLabel": False}},
        "topics": {t: {"visible": True, **s} for t, s in spec.scene.items() if t in present},
    }}
    side: list[str] = []
    for k, (title, series) in enumerate(spec.plots):
        paths = _series(series, present)
        if paths:
            pid = f"Plot!{k}"
            config[pid] = {"title": title, "paths": paths, "showLegend": True, "legendDisplay": "top",
                           "showXAxisLabels": True, "showYAxisLabels": True, "isSynced": True,
                           "xAxisVal": "timestamp"}
            side.append(pid)
    states = _series(spec.states, present)
    if states:
        config["StateTransitions!states"] = {"paths": states, "isSynced": True}
        side.append("StateTransitions!states")
    for topic in spec.raw:
        if topic in present:
            pid = f"RawMessages!{topic.strip('/').replace('/', '_')}"
            config[pid] = {"topicPath": topic, "diffEnabled": False}
            side.append(pid)
    tree: str | dict[str, Any] = "3D!scene"
    if side:
        tree = {"first": "3D!scene", "second": _split(side, "column"), "direction": "row",
                "splitPercentage": 55.0}
    return {"configById": config, "layout": tree, "globalVariables": {}, "userNodes": {},
            "linkedGlobalVariables": [], "playbackConfig": {"speed": 1.0}}


def layout_topics(layout: Mapping[str, Any]) -> set[str]:
    """Every topic a layout made by ``foxglove_layout`` refers to."""
    found: set[str] = set()
    for panel in layout["configById"].values():
        found.update(panel.get("topics", {}))
        found.update(_topic(p["value"]) for p in panel.get("paths", ()))
        if "topicPath" in panel:
            found.add(_topic(panel["topicPath"]))
    return found


def write_layout(path: Path, spec: LayoutSpec, topics: Collection[str]) -> None:
    """Write ``foxglove_layout(spec, topics)`` to ``path`` (JSON, stable key order)."""
    Path(path).write_text(json.dumps(foxglove_layout(spec, topics), indent=2) + "\n", encoding="utf-8")

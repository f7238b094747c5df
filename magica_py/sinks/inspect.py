"""`magica-py inspect FILE.rrd`: a summary of a recording read back from the file.

Prints frames, duration, entities (rows per entity), particle count per cloth, metric
min / mean / max, the event log and whether replay data and a blueprint are present.
``--json`` prints the same summary as JSON (for scripts and tests).
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from magica_py.sinks import layout as L
from magica_py.sinks.readback import Recording, RecordingError


# Units of the metrics a recording holds (docs/recordings.md): the sink converts ``time.*`` to
# ms and logs everything else as the systems reported it.
METRIC_UNITS = {"steps": "steps", "max_edge_stretch": "ratio", "max_penetration": "m", "max_speed": "m/s",
                "cloth/kernel": "s", "cloth/propagate": "s", "cloth/steps": "particle-steps",
                "cloth/simulation_steps": "steps", "frame/fixed_updates": "count"}


def metric_unit(name: str) -> str:
    """The unit of metric ``name`` (``time/late_update`` -> ``ms``); "" when unknown."""
    if name.startswith("time/"):
        return "ms"
    return METRIC_UNITS.get(name, "")


def summarize(path) -> dict:
    rec = Recording(path)
    frames = rec.timeline_values(L.TIMELINE_FRAME)
    times = rec.timeline_values(L.TIMELINE_SIM_TIME)
    entities = {}
    for entity in rec.entities:
        # frames with data (components sent separately would double-count rows)
        logged = [b.column(L.TIMELINE_FRAME).to_numpy() for b in rec.temporal.get(entity, [])
                  if L.TIMELINE_FRAME in b.schema.names]
        rows = np.unique(np.concatenate(logged)).size if logged else 0
        entities[entity] = {"rows": int(rows), "static": bool(rec.static.get(entity))}
    cloths = {}
    prefix = f"/{L.CLOTHS}/"
    for entity in rec.entities:
        if entity.startswith(prefix) and entity.endswith("/particles") and rec.temporal.get(entity):
            _, rows = rec.rows(entity, "Points3D:positions")
            cloths[entity[len(prefix):-len("/particles")]] = int(rows[0].shape[0]) if rows else 0
    metrics = {}
    for entity in rec.entities:
        if entity.startswith(f"/{L.METRICS}/") and rec.temporal.get(entity):
            _, values = rec.scalars(entity)
            finite = values[np.isfinite(values)]
            if finite.size:
                name = entity[len(L.METRICS) + 2:]
                metrics[name] = {"min": float(finite.min()), "mean": float(finite.mean()),
                                 "max": float(finite.max()), "count": int(finite.size), "unit": metric_unit(name)}
    events = [{"frame": f, "text": t} for f, t in rec.text_rows(f"/{L.EVENTS}", "TextLog:text")]
    replay_nodes = 0
    if f"/{L.REPLAY_NODES}" in rec.entities:
        replay_nodes = len([n for n in rec.static_value(f"/{L.REPLAY_NODES}", "names") if n])
    scene = ""
    if f"/{L.REPLAY_SCENE}" in rec.entities:
        try:
            scene = (rec.static_value(f"/{L.REPLAY_SCENE}", "name") or [""])[0]
        except RecordingError:
            scene = ""
    return {
        "file": str(path),
        "scene": scene,
        "frames": int(frames.size),
        "first_frame": int(frames[0]) if frames.size else None,
        "last_frame": int(frames[-1]) if frames.size else None,
        "duration": float((times[-1] - times[0]) / 1e9) if times.size else 0.0,
        "sim_time_end": float(times[-1] / 1e9) if times.size else 0.0,
        "entities": entities,
        "particles": int(sum(cloths.values())),
        "cloths": cloths,
        "metrics": metrics,
        "events": events,
        "replay": {"available": replay_nodes > 0, "driven_transforms": replay_nodes},
        "blueprint": rec.blueprint_count > 0,
    }


def format_summary(s: dict, max_entities: int = 40, max_events: int = 30) -> str:
    lines = [f"recording   {s['file']}" + (f"  (scene {s['scene']!r})" if s["scene"] else "")]
    if s["frames"]:
        lines.append(f"frames      {s['frames']} (frame {s['first_frame']}..{s['last_frame']})")
    else:
        lines.append("frames      0")
    lines.append(f"duration    {s['duration']:.3f} s of simulation time (ends at {s['sim_time_end']:.3f} s)")
    lines.append(f"particles   {s['particles']} in {len(s['cloths'])} cloth(s)")
    for name, n in list(s["cloths"].items())[:10]:
        lines.append(f"            {name}: {n}")
    if len(s["cloths"]) > 10:
        lines.append(f"            ... {len(s['cloths']) - 10} more")
    lines.append(f"replay      {'yes' if s['replay']['available'] else 'no'}"
                 + (f" ({s['replay']['driven_transforms']} driven transforms)" if s["replay"]["available"] else ""))
    lines.append(f"blueprint   {'yes' if s['blueprint'] else 'no'}")
    lines.append(f"entities    {len(s['entities'])}")
    for entity, info in list(s["entities"].items())[:max_entities]:
        lines.append(f"            {entity}  rows={info['rows']}" + ("  +static" if info["static"] else ""))
    if len(s["entities"]) > max_entities:
        lines.append(f"            ... {len(s['entities']) - max_entities} more (use --json for all)")
    if s["metrics"]:
        lines.append("metrics     name                           unit                    min         mean          max")
        for name, m in s["metrics"].items():
            unit = m.get("unit", metric_unit(name)) or "-"
            lines.append(f"            {name:<30} {unit:<15} {m['min']:>12.6g} {m['mean']:>12.6g} "
                         f"{m['max']:>12.6g}")
    lines.append(f"events      {len(s['events'])}")
    for e in s["events"][:max_events]:
        lines.append(f"            frame {e['frame']:>6}  {e['text']}")
    if len(s["events"]) > max_events:
        lines.append(f"            ... {len(s['events']) - max_events} more")
    return "\n".join(lines)


def main_inspect(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="magica-py inspect",
                                     description="Summarise a recording: frames, duration, entities, particles, "
                                                 "metric ranges and events, read back from the .rrd file.")
    parser.add_argument("recording", help="an .rrd file")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument("--all", action="store_true", help="list every entity and event")
    args = parser.parse_args(argv)
    try:
        summary = summarize(args.recording)
    except RecordingError as exc:
        print(f"magica-py inspect: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        big = 10 ** 9 if args.all else None
        print(format_summary(summary, **({"max_entities": big, "max_events": big} if big else {})))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main_inspect())

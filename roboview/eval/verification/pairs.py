"""A bias found, seen: an episode and its twin under another value of its factor, replayed side by side.

An episode is a function of (instance, repeat): its context, its seed and the policy run.json records. Its twin is
the same (context, repeat) with one factor set otherwise: by default the control arm (the context's all-baseline
instance: every visual factor at its baseline, the same seed), or the instance of the same split whose value is
named. `replay_pair` re-runs both here with the recorded policy, keeps every camera the policy saw, its actions and
the end effector's path, and finds where they part: the first step whose actions differ by more than a tolerance (the
largest absolute difference of any action dimension). Before that step the two episodes saw different pictures and
did the same thing; from it on they act differently.

A replay stands for the recorded episode only when it reproduces it. Each replayed side is compared with its row
(success, steps, failure reason). A mismatch is said plainly, with what the folder records about why it can happen:
a policy that is not reproducible from the episode seed (a served model sampling its actions; `reproducible` on its
config), or rows whose stack conformance was `different` from the benchmark's (another renderer or simulator).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roboview.eval.running.results import is_counted

REPLAYED = ("success", "steps", "failure_reason")
TOLERANCE = 1e-6


@dataclass
class Side:
    """One episode of a pair: its instance record, the row the folder records (None when it ran no such episode),
    and its replay."""

    label: str
    record: dict
    row: dict | None
    replayed: dict = field(default_factory=dict)
    frames: dict[str, list[bytes]] = field(default_factory=dict)
    actions: np.ndarray | None = None
    ee_path: np.ndarray | None = None

    def mismatch(self) -> list[str]:
        """How the replay differs from the recorded row ([] when it matches, or when no row is recorded)."""
        if self.row is None:
            return []
        return [
            f"{k} {self.row.get(k)!r} → {self.replayed.get(k)!r}"
            for k in REPLAYED
            if (self.row.get(k) or None) != (self.replayed.get(k) or None)
        ]


@dataclass
class Pair:
    value: Side
    other: Side
    repeat: int
    parting: int | None
    parting_gap: float
    tolerance: float
    faithful: bool
    why: list[str]


def parting_step(a: np.ndarray, b: np.ndarray, tolerance: float = TOLERANCE) -> tuple[int | None, float]:
    """The first step whose actions differ by more than `tolerance` (largest absolute difference of a dimension),
    and that difference; when none does over the shorter episode, the step one of them ended at if their lengths
    differ (None, 0 when they are the same episode)."""
    n = min(len(a), len(b))
    gaps = np.abs(np.asarray(a[:n], float) - np.asarray(b[:n], float)).max(axis=1) if n else np.zeros(0)
    over = np.flatnonzero(gaps > tolerance)
    if len(over):
        return int(over[0]), float(gaps[over[0]])
    return (n, 0.0) if len(a) != len(b) else (None, 0.0)


def twin_of(item, items: dict[str, Any], against: str = ""):
    """The benchmark item `item`'s episode is paired with: the context's all-baseline instance (the control arm;
    from `item`'s split if it holds one, else any split; the split's reference value where its factor declares one,
    `Factor.reference`) or, with `against`, the instance of `item`'s split and
    context whose value is `against`. ValueError, one line, naming what exists when there is none."""
    from roboview.variation.factors import FACTORS, baselines, visual_factors

    context, split = item.record["context_id"], item.record["split"]
    same = [i for i in items.values() if i.record["context_id"] == context]
    varied = item.instance.varied
    # A factor declaring its own control arm (scene_text's blank card) pairs with that value of the split.
    against = against or (FACTORS[varied[0]].reference if len(varied) == 1 else "")
    if against:
        found = [i for i in same if i.record["split"] == split and i.record["value"] == against]
        if not found:
            values = sorted({i.record["value"] for i in same if i.record["split"] == split})
            raise ValueError(
                f"split {split} holds no value {against!r} in context {context}; its values there: {', '.join(values)}"
            )
        return found[0]
    base = baselines(item.instance.task)
    control = [i for i in same if all(i.instance.get(f) == base[f] for f in visual_factors())]
    if not control:
        raise ValueError(
            f"the benchmark holds no all-baseline instance of context {context} (its control arm); "
            "name a value of the split with --against"
        )
    control.sort(key=lambda i: i.record["split"] != split)  # the split's own control first
    return control[0]


def discordant(
    rows: list[dict], bench, split: str, value: str, against: str = "", limit: int = 3
) -> list[tuple]:
    """The (instance_id, repeat) episodes of `value` in `split` whose outcome differs from their twin's (the control
    arm, or `against`), failures of the value first: the pairs that carry a difference. ValueError naming the split's
    values when `value` is not one of them."""
    items = {i.record["instance_id"]: i for its in bench.splits.values() for i in its}
    mine = [r for r in rows if r["split"] == split and str(r["value"]) == value and is_counted(r)]
    if not mine:
        values = sorted({str(r["value"]) for r in rows if r["split"] == split})
        if not values:
            splits = sorted({r["split"] for r in rows})
            raise ValueError(f"the results hold no split {split!r}; their splits: {', '.join(splits)}")
        raise ValueError(
            f"split {split} holds no value {value!r} in these results; its values: {', '.join(values)}"
        )
    outcome = {(r["instance_id"], int(r["repeat"])): bool(r["success"]) for r in rows}
    found = []
    for r in mine:
        twin = twin_of(items[r["instance_id"]], items, against)
        other = outcome.get((twin.record["instance_id"], int(r["repeat"])))
        if other is not None and other != bool(r["success"]):
            found.append((r["instance_id"], int(r["repeat"]), bool(r["success"])))
    found.sort(key=lambda f: (f[2], f[1], f[0]))  # the value's failures (its twin succeeded) first
    return [(i, rep) for i, rep, _ in found[:limit]]


@dataclass
class Loaded:
    """A results folder read once for every pair replayed from it: its rows and run.json, its benchmark and the
    benchmark's items, and this machine's conformance verdict on that benchmark."""

    rows: list[dict]
    run: dict
    bench: Any
    items: dict[str, Any]
    here: str


def load(results: str | Path, benchmark: str | Path | None = None) -> Loaded:
    """Read a results folder and its benchmark (default: the one its provenance names) for replaying pairs."""
    from roboview.benchmark import conformance
    from roboview.benchmark.format import load_benchmark
    from roboview.eval.verification.results import benchmark_path, read_table

    table, run = read_table(Path(results))
    bench = load_benchmark(benchmark_path(results, benchmark))
    items = {i.record["instance_id"]: i for its in bench.splits.values() for i in its}
    here = conformance.at_start(Path(bench.path), bench.version).verdict  # a cached verdict is reused
    return Loaded(table.to_pylist(), run, bench, items, here)


def replay_pair(
    results: str | Path,
    instance_id: str,
    repeat: int = 0,
    against: str = "",
    benchmark: str | Path | None = None,
    tolerance: float = TOLERANCE,
    replayer=None,
    loaded: Loaded | None = None,
) -> Pair:
    """Re-run episode (`instance_id`, `repeat`) of a results folder and its twin here, with the recorded policy
    (`loaded`: the folder already read by `load`; `replayer`: workers kept across calls)."""
    from roboview.eval.running.rollout import WorkItem
    from roboview.eval.verification.replay import Replayer

    loaded = loaded or load(results, benchmark)
    if instance_id not in loaded.items:
        raise ValueError(f"instance {instance_id!r} is not in benchmark {loaded.bench.version}")
    item = loaded.items[instance_id]
    twin = twin_of(item, loaded.items, against)
    recorded = {(r["instance_id"], int(r["repeat"])): r for r in loaded.rows}
    own = replayer is None
    replayer = replayer or Replayer()
    try:
        policy = replayer.policy(loaded.run)
        worker = replayer.worker(loaded.run, policy, item.instance.task, record_media=True)
        a, b = (
            _side(worker.run(WorkItem(it, repeat)), it, recorded.get((it.record["instance_id"], repeat)))
            for it in (item, twin)
        )
    finally:
        if own:
            replayer.close()
    parting, gap = parting_step(a.actions, b.actions, tolerance)
    why = [
        f"{s.label}: the replay ended differently from its row ({', '.join(s.mismatch())})"
        for s in (a, b)
        if s.mismatch()
    ]
    faithful = not why
    return Pair(a, b, repeat, parting, gap, tolerance, faithful, why + _caveats(policy, loaded, (a, b)))


def _side(result, item, row: dict | None) -> Side:
    """A replayed episode (its row, frames, actions and path) beside its recorded row."""
    actions = np.asarray(result.actions) if result.actions is not None else None
    label = f"{item.record['factor']}={item.record['value']}"
    return Side(label, item.record, row, result.row, result.frames or {}, actions, result.ee_path)


def _caveats(policy, loaded: Loaded, sides) -> list[str]:
    """What the folder and this machine say about why a replay may not stand for its row."""
    out = []
    if not getattr(policy, "reproducible", True):
        out.append(
            f"{loaded.run['policy']} is not reproducible from the episode seed (its config declares reproducible = "
            "False: a served or sampled model draws from its own randomness), so a replay may differ from the recorded run"
        )
    if loaded.here == "different":
        out.append(
            "this machine renders or simulates the benchmark differently from the machine that built it (its "
            "conformance check says `different`: roboview-verify --benchmark.path shows the figures)"
        )
    if "different" in {s.row.get("conformance") for s in sides if s.row}:
        out.append(
            "the recorded episodes ran on a stack whose conformance with the benchmark was `different` (their rows' "
            "conformance column): another renderer or simulator may give other episodes"
        )
    return out


def _blueprint(pair: Pair, cameras: list[str]):
    """Two columns, the value's episode and its twin (each camera, then the actions), over the paths and events."""
    import rerun.blueprint as rrb

    def column(key: str, side: Side):
        views = [
            rrb.Spatial2DView(origin=f"pair/{key}/camera/{c}", name=f"{side.label}: {c}") for c in cameras
        ]
        return rrb.Vertical(
            *views, rrb.TimeSeriesView(origin=f"pair/{key}/action", name=f"{side.label}: action")
        )

    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(column("value", pair.value), column("other", pair.other)),
            rrb.Horizontal(rrb.Spatial3DView(origin="pair/paths"), rrb.TextLogView(origin="pair/events")),
        )
    )


def record(pair: Pair, path: str | Path) -> Path:
    """One Rerun recording of both episodes side by side: each camera the policy saw, its actions, the end effector's
    path, the outcome, and the step where the actions part. Opens in the viewer laid out in two columns."""
    import rerun as rr

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cameras = sorted(pair.value.frames)
    rec = rr.RecordingStream("roboview_pair")
    rec.save(str(path), default_blueprint=_blueprint(pair, cameras))
    for key, side in (("value", pair.value), ("other", pair.other)):
        _log_side(rec, key, side, cameras, pair.repeat)
    if pair.parting is not None:
        rec.set_time("step", sequence=pair.parting)
        note = f"actions part at step {pair.parting} (|Δ| {pair.parting_gap:.3g})"
        rec.log("pair/events", rr.TextLog(note, level="WARN"))
    rec.flush()
    rr.disconnect(recording=rec)
    return path


def _log_side(rec, key: str, side: Side, cameras: list[str], repeat: int) -> None:
    import rerun as rr

    color = [230, 80, 60] if key == "value" else [40, 120, 255]
    facts = "\n".join(
        f"{k}: {side.record[k]}" for k in ("instance_id", "split", "factor", "value", "context_id")
    )
    rec.log(f"pair/{key}/instance", rr.TextDocument(f"{facts}\nrepeat: {repeat}"), static=True)
    steps = 0 if side.actions is None else len(side.actions)
    for step in range(len(side.ee_path) if side.ee_path is not None else 0):
        rec.set_time("step", sequence=step)
        for cam in cameras:
            if step < len(side.frames.get(cam, [])):
                image = rr.EncodedImage(contents=side.frames[cam][step], media_type="image/jpeg")
                rec.log(f"pair/{key}/camera/{cam}", image)
        if step < steps:
            rec.log(f"pair/{key}/action", rr.Scalars(np.asarray(side.actions[step], float)))
        rec.log(f"pair/paths/{key}/ee", rr.Points3D(side.ee_path[step : step + 1], radii=0.01, colors=color))
    if side.ee_path is not None and len(side.ee_path):
        rec.log(f"pair/paths/{key}/ee_path", rr.LineStrips3D([side.ee_path], colors=color), static=True)
    rec.set_time("step", sequence=max(steps - 1, 0))
    won = bool(side.replayed.get("success"))
    ended = "success" if won else f"failure: {side.replayed.get('failure_reason')}"
    rec.log("pair/events", rr.TextLog(f"{side.label}: {ended}", level="INFO" if won else "WARN"))


# ---- strips: the report's picture of a pair ---------------------------------------------------------------------
STRIP_SIDE = 160  # pixels a frame is drawn at in a strip


def strip_steps(pair: Pair) -> list[tuple[str, int, int]]:
    """The strip's columns: (title, step of the twin, step of the value's episode): the first step, the parting step
    (when they part), and each episode's end."""
    ends = (len(pair.other.ee_path) - 1, len(pair.value.ee_path) - 1)
    columns = [("step 0", 0, 0)]
    if pair.parting is not None and 0 < pair.parting < min(ends):
        columns.append((f"step {pair.parting}: actions part", pair.parting, pair.parting))
    columns.append((f"end (steps {ends[0]} / {ends[1]})", *ends))
    return columns


def strip_image(pair: Pair, camera: str):
    """Frames of `camera` at the strip's steps (strip_steps): the twin above, the value's episode below, each row
    labelled with its value and outcome."""
    import io

    from PIL import Image, ImageDraw

    columns = strip_steps(pair)
    label_w, head_h = 150, 18
    image = Image.new("RGB", (label_w + STRIP_SIDE * len(columns), head_h + 2 * STRIP_SIDE), "white")
    draw = ImageDraw.Draw(image)
    for c, (title, _, _) in enumerate(columns):
        draw.text((label_w + c * STRIP_SIDE + 4, 3), title, fill="black")
    for r, side in enumerate((pair.other, pair.value)):
        y = head_h + r * STRIP_SIDE
        won = bool(side.replayed.get("success"))
        draw.text((4, y + 4), side.label, fill="black")
        draw.text((4, y + 20), "success" if won else "failure:", fill="darkgreen" if won else "darkred")
        if not won:  # its reason, wrapped to the label column
            reason = str(side.replayed.get("failure_reason") or "")
            for i in range(0, min(len(reason), 66), 22):
                draw.text((4, y + 36 + 14 * (i // 22)), reason[i : i + 22], fill="darkred")
        frames = side.frames[camera]
        for c, column in enumerate(columns):
            step = min(column[1 + r], len(frames) - 1)
            frame = Image.open(io.BytesIO(frames[step])).convert("RGB").resize((STRIP_SIDE, STRIP_SIDE))
            image.paste(frame, (label_w + c * STRIP_SIDE, y))
    return image


def make_strips(metrics: dict, sources: list[dict], out: Path, per_value: int = 1) -> dict[str, Any]:
    """For each value that differs from its control arm (p_control < 0.05), its `per_value` strongest discordant
    pairs replayed and drawn as strips (`strip_<n>.png` in `out`): metrics.json's `strips` {"drawn": [...],
    "skipped": [...]}, each drawn strip with its policy, split, value, episode, parting step, faithfulness and the
    command that replays it; a value whose pairs cannot be replayed here is skipped with the reason."""
    from roboview.eval.statistics.metrics import policy_layouts
    from roboview.eval.verification.replay import Replayer

    drawn: list[dict] = []
    skipped: list[str] = []
    folders = {p: Path(s["path"]).parent for s in sources for p in s.get("policies", [])}
    replayer = Replayer()
    try:
        for policy, layout in policy_layouts(metrics).items():
            wanted = [
                (split, value)
                for split, m in layout.get("splits", {}).items()
                for value, v in m.get("per_value", {}).items()
                if v.get("p_control") is not None and v["p_control"] < 0.05
            ]
            if not wanted:
                continue
            folder = folders.get(policy)
            try:
                loaded = load(folder)
            except Exception as exc:  # any reason the episodes cannot be replayed here is the strip's answer
                skipped.append(f"{policy}: {type(exc).__name__}: {exc}")
                continue
            for split, value in wanted:
                try:
                    for instance, repeat in discordant(
                        loaded.rows, loaded.bench, split, value, "", per_value
                    ):
                        pair = replay_pair(folder, instance, repeat, replayer=replayer, loaded=loaded)
                        camera = next(iter(pair.value.frames))
                        name = f"strip_{len(drawn) + 1}.png"
                        strip_image(pair, camera).save(out / name)
                        drawn.append(
                            {
                                "policy": policy,
                                "split": split,
                                "value": value,
                                "against": pair.other.record["value"],
                                "instance_id": instance,
                                "repeat": repeat,
                                "camera": camera,
                                "parting": pair.parting,
                                "faithful": pair.faithful,
                                "file": name,
                                "command": f"roboview-pair --results={folder} --instance={instance} --repeat={repeat}",
                            }
                        )
                except Exception as exc:  # a policy that cannot be rebuilt or reached here
                    skipped.append(f"{policy} {split}={value}: {type(exc).__name__}: {exc}")
    finally:
        replayer.close()
    return {"drawn": drawn, "skipped": skipped}

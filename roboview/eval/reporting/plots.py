"""PNG figures of a report, drawn from the metrics dict only (never from raw episodes).

Why from the dict: a figure and the table next to it then show the same numbers. Each figure
needs one split; when no policy has it the figure is skipped and the reason goes into report.md.
Success counts behind the Clopper–Pearson intervals are recovered as round(sr × n_episodes), exact because
sr was computed as count / n.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: reports are written on machines without a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from roboview.eval.statistics.significance import logistic_trend  # noqa: E402
from roboview.eval.statistics.tables import rate_interval  # noqa: E402
from roboview.variation.colors import CATEGORIES, COLORS  # noqa: E402
from roboview.variation.factors import (  # noqa: E402
    DIST_STEP_M,
    EULER_STEPS_DEG,
    N_ORBIT_POSES_PER_RING,
    N_ORBIT_RINGS,
    parse_camera_pose,
    parse_dist_scale,
    parse_euler,
    visual_factors,
)
from roboview.variation.instances import DEFAULT_TASK, split_task  # noqa: E402

Layouts = dict[str, dict[str, Any]]
_MARKERS = "osD^vP*X"
_OR_LIMIT = 100.0  # forest plots clip odds ratios (and their intervals) to [1/100, 100]
_DPI = 100


def _per_value(layouts: Layouts, split: str, key: str = "splits") -> dict[str, dict[str, dict]]:
    """policy → per_value of `split`, for the policies that have it."""
    return {p: lay[key][split]["per_value"] for p, lay in layouts.items() if split in lay[key]}


def _rate_err(stats: list[dict]) -> np.ndarray:
    """Asymmetric error bars (2, n) around each SR from its Clopper–Pearson interval."""
    err = []
    for s in stats:
        lo, hi = rate_interval(round(s["sr"] * s["n_episodes"]), s["n_episodes"])
        err.append((s["sr"] - lo, hi - s["sr"]))
    return np.clip(np.array(err).T, 0, None)  # k/n recomputed from sr may differ by float noise


def _save(fig: plt.Figure, path: Path) -> None:
    fig.savefig(path, dpi=_DPI)
    plt.close(fig)


def _grid_axes(n: int, width: float, height: float) -> tuple[plt.Figure, list[plt.Axes]]:
    fig, axes = plt.subplots(1, n, figsize=(width * n, height), squeeze=False, layout="constrained")
    return fig, list(axes[0])


def _heatmap(ax: plt.Axes, grid: np.ndarray, rows: list[str], cols: list[str], title: str) -> Any:
    image = ax.imshow(grid, vmin=0, vmax=1, cmap="viridis", aspect="auto")
    ax.set_xticks(range(len(cols)), cols, rotation=45 if max(map(len, cols)) > 3 else 0, ha="right")
    ax.set_yticks(range(len(rows)), rows)
    for (i, j), v in np.ndenumerate(grid):
        if not math.isnan(v):
            ax.text(
                j,
                i,
                f"{100 * v:.0f}",
                ha="center",
                va="center",
                fontsize=7,
                color="white" if v < 0.5 else "black",
            )
    ax.set_title(title)
    return image


def category_color(category: str) -> str:
    """Bar color of a basic category: the CSS color of the same name (a baseline label, `original`: gray)."""
    return COLORS[category].hex if category in COLORS else "#808080"


def _category(value: str) -> str | None:
    """The basic color category of a CSS color value (None: a baseline label, no color)."""
    return COLORS[value].category if value in COLORS else None


def category_stats(per: dict[str, dict[str, dict]]) -> dict[str, list[dict]]:
    """Per basic color category that any policy's episodes cover: per policy (in `per`'s order) its pooled SR and
    episodes (SR NaN for a policy without episodes there). Categories the benchmark holds no color of are left
    out, so a chart never shows an absent category as a 0 % bar. A value that is no CSS color is a world's baseline
    label (LIBERO's and Meta-World's `original`: the object's own look) and is its own bar, first, under its name."""
    out: dict[str, list[dict]] = {}
    labels = list(dict.fromkeys(v for values in per.values() for v in values if v not in COLORS))
    for category in [*labels, *CATEGORIES]:
        stats = []
        for values in per.values():
            members = [s for v, s in values.items() if v == category or _category(v) == category]
            n = sum(s["n_episodes"] for s in members)
            k = sum(round(s["sr"] * s["n_episodes"]) for s in members)
            stats.append({"sr": k / n if n else math.nan, "n_episodes": n})
        if any(s["n_episodes"] for s in stats):
            out[category] = stats
    return out


def plot_color_categories(layouts: Layouts, path: Path) -> None:
    """SR per basic color category (pooled over its colors' episodes), Clopper–Pearson 95 % error bars; only the
    categories the episodes cover (the title names the absent ones)."""
    per = _per_value(layouts, "color")
    table = category_stats(per)
    names = list(table)
    fig, ax = plt.subplots(figsize=(10, 4), layout="constrained")
    width = 0.8 / len(per)
    for i, policy in enumerate(per):
        shown = [j for j, c in enumerate(names) if table[c][i]["n_episodes"]]
        ax.bar(
            np.array(shown) + (i - (len(per) - 1) / 2) * width,
            [table[names[j]][i]["sr"] for j in shown],
            width,
            yerr=_rate_err([table[names[j]][i] for j in shown]),
            capsize=2,
            label=policy,
            color=[category_color(names[j]) for j in shown],
            edgecolor="black",
            hatch="/" * i,
        )
    ax.set_xticks(range(len(names)), names)
    absent = [c for c in CATEGORIES if c not in table]
    ax.set(
        ylabel="success rate",
        ylim=(0, 1.05),
        title="Success rate by basic color category"
        + (f"\n(no color of the benchmark is {', '.join(absent)})" if absent else ""),
    )
    if len(per) > 1:  # bars wear their category's color, so the legend shows each policy's hatch
        ax.legend(
            handles=[
                Patch(facecolor="white", edgecolor="black", hatch="/" * i, label=p) for i, p in enumerate(per)
            ]
        )
    _save(fig, path)


def plot_color_lab(layouts: Layouts, path: Path) -> None:
    """SR per color against CIELAB chroma C*ab and lightness L*, each dot in its own color."""
    fig, axes = _grid_axes(2, 5, 4)
    for i, (policy, values) in enumerate(_per_value(layouts, "color").items()):
        known = [(COLORS[v], s["sr"]) for v, s in values.items() if v in COLORS]
        lab = np.array([c.lab for c, _ in known])
        sr = [s for _, s in known]
        faces = [c.hex for c, _ in known]
        for ax, x in zip(axes, (np.hypot(lab[:, 1], lab[:, 2]), lab[:, 0])):
            ax.scatter(
                x,
                sr,
                c=faces,
                edgecolors="black",
                linewidths=0.4,
                marker=_MARKERS[i % len(_MARKERS)],
                label=policy,
            )
    axes[0].set(xlabel="CIELAB chroma C*ab", ylabel="success rate", ylim=(-0.05, 1.05))
    axes[1].set(xlabel="CIELAB lightness L*", ylim=(-0.05, 1.05))
    axes[0].set_title("Success rate vs chroma")
    axes[1].set_title("Success rate vs lightness")
    if len(layouts) > 1:
        axes[1].legend()
    _save(fig, path)


def plot_camera_pose(layouts: Layouts, path: Path) -> None:
    """SR over the 21 orbital poses as a ring × azimuth-index grid, one panel per policy."""
    per = _per_value(layouts, "camera_pose")
    fig, axes = _grid_axes(len(per), 5, 2.6)
    for ax, (policy, values) in zip(axes, per.items()):
        grid = np.full((N_ORBIT_RINGS, N_ORBIT_POSES_PER_RING), math.nan)
        for value, s in values.items():
            where = parse_camera_pose(value)
            if where is not None:
                grid[where] = s["sr"]
        image = _heatmap(
            ax,
            grid,
            [f"ring {r}" for r in range(N_ORBIT_RINGS)],
            [str(k) for k in range(N_ORBIT_POSES_PER_RING)],
            policy,
        )
        ax.set_xlabel("pose index on ring")
    fig.colorbar(image, ax=axes, label="success rate")
    fig.suptitle("Success rate by orbital camera pose")
    _save(fig, path)


def plot_camera_euler(layouts: Layouts, path: Path) -> None:
    """SR over (yaw, pitch) as a 3 × 3 heatmap, yaw rows and pitch columns."""
    per = _per_value(layouts, "camera_euler")
    fig, axes = _grid_axes(len(per), 3.6, 3.2)
    steps = list(EULER_STEPS_DEG)
    for ax, (policy, values) in zip(axes, per.items()):
        grid = np.full((len(steps), len(steps)), math.nan)
        for value, s in values.items():
            yaw, pitch = parse_euler(value)
            grid[steps.index(yaw), steps.index(pitch)] = s["sr"]
        _heatmap(ax, grid, [f"yaw {y}°" for y in steps], [f"{p}°" for p in steps], policy)
        ax.set_xlabel("pitch")
    fig.suptitle("Success rate by camera Euler offset")
    _save(fig, path)


def plot_dist_scale(layouts: Layouts, path: Path) -> None:
    """SR against how far the cameras moved back (0.05·k m), Clopper–Pearson 95 % band."""
    fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
    for i, (policy, values) in enumerate(_per_value(layouts, "dist_scale").items()):
        items = sorted(values.items(), key=lambda kv: parse_dist_scale(kv[0]))
        x = [DIST_STEP_M * parse_dist_scale(v) for v, _ in items]
        sr = np.array([s["sr"] for _, s in items])
        err = _rate_err([s for _, s in items])
        ax.plot(x, sr, marker=_MARKERS[i % len(_MARKERS)], label=policy)
        ax.fill_between(x, sr - err[0], sr + err[1], alpha=0.2)
    ax.set(
        xlabel="camera moved back along its optical axis (m)",
        ylabel="success rate",
        ylim=(0, 1.05),
        title="Success rate vs camera distance",
    )
    ax.legend()
    _save(fig, path)


def plot_color_x_camera_pose(layouts: Layouts, path: Path) -> None:
    """SR of every (color, pose) pair: pose rows, color columns, as the paper's heatmaps."""
    per = _per_value(layouts, "color_x_camera_pose", key="interactions")
    fig, axes = _grid_axes(len(per), 4.5, 6)
    for ax, (policy, values) in zip(axes, per.items()):
        pairs = [key.split("|") for key in values]
        colors = list(dict.fromkeys(c for c, _ in pairs))
        poses = list(dict.fromkeys(p for _, p in pairs))
        grid = np.full((len(poses), len(colors)), math.nan)
        for (color, pose), s in zip(pairs, values.values()):
            grid[poses.index(pose), colors.index(color)] = s["sr"]
        image = _heatmap(ax, grid, poses, colors, policy)
    fig.colorbar(image, ax=axes, label="success rate")
    fig.suptitle("Success rate by object color and camera pose")
    _save(fig, path)


def plot_forest(split: str) -> Callable[[Layouts, Path], None]:
    """Forest plot of a single-factor split: each value's CMH odds ratio against the other values,
    95 % interval, colored where its Benjamini–Hochberg q < 0.05 (red: harder, blue: easier)."""

    def draw(layouts: Layouts, path: Path) -> None:
        per_policy = _per_value(layouts, split)
        n_rows = max(len(pv) for pv in per_policy.values())
        fig, axes = _grid_axes(len(per_policy), 5.0, max(3.0, 0.16 * n_rows + 1.2))
        for ax, (policy, per_value) in zip(axes, per_policy.items()):
            names = list(per_value)
            for y, name in enumerate(names):
                s = per_value[name]
                if s["p_value"] is None:
                    continue  # no informative stratum: nothing was compared
                # An odds ratio of 0 (never succeeds where others do) or ∞ (stored as null with a
                # defined p-value: never fails where others do) sits at the axis edge as a triangle.
                odds, marker = s["odds_ratio"], "o"
                if odds is None or odds > _OR_LIMIT:
                    odds, marker = _OR_LIMIT, ">"
                elif odds < 1 / _OR_LIMIT:
                    odds, marker = 1 / _OR_LIMIT, "<"
                significant = s["q_value"] is not None and s["q_value"] < 0.05
                color = ("tab:red" if odds < 1 else "tab:blue") if significant else "0.6"
                if s["odds_ratio_ci95"] is not None:
                    lo, hi = s["odds_ratio_ci95"]
                    ax.plot([max(lo, 1 / _OR_LIMIT), min(hi, _OR_LIMIT)], [y, y], color=color, lw=1.2)
                ax.plot(odds, y, marker, color=color, ms=3.5)
            ax.axvline(1.0, color="k", lw=0.8, ls="--")
            ax.set_xscale("log")
            ax.set_xlim(1 / _OR_LIMIT / 1.5, _OR_LIMIT * 1.5)
            ax.set_yticks(range(len(names)), names, fontsize=6 if len(names) > 40 else 8)
            ax.set_ylim(len(names) - 0.5, -0.5)  # first value on top, no empty margin
            ax.set_xlabel("odds ratio vs the other values (CMH, 95 % CI)")
            ax.set_title(policy)
        handles = [
            Patch(color="tab:red", label="harder, q < 0.05"),
            Patch(color="tab:blue", label="easier, q < 0.05"),
            Patch(color="0.6", label="not significant"),
        ]
        fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize=8)
        fig.suptitle(f"{split}: which values differ from the rest")
        _save(fig, path)

    return draw


def plot_lighting(layouts: Layouts, path: Path) -> None:
    """SR over key-light intensity (rows) × direction (columns)."""
    from roboview.variation.factors.lighting import (
        INTENSITIES,
        POSITIONS,
    )

    per = _per_value(layouts, "lighting")
    fig, axes = _grid_axes(len(per), 3.8, 3.2)
    intensities, directions = list(INTENSITIES), list(POSITIONS)
    for ax, (policy, values) in zip(axes, per.items()):
        grid = np.full((len(intensities), len(directions)), math.nan)
        for value, s in values.items():
            name = "normal_top" if value == "default" else value
            grid[intensities.index(name.split("_")[0]), directions.index(name.split("_")[1])] = s["sr"]
        _heatmap(ax, grid, intensities, directions, policy)
    fig.suptitle("Success rate by key light (intensity × direction)")
    _save(fig, path)


def _bars(layouts: Layouts, split: str, path: Path, title: str, order: list[str]) -> None:
    per = _per_value(layouts, split)
    fig, ax = plt.subplots(figsize=(max(6, 0.7 * len(order) * len(per)), 4), layout="constrained")
    width = 0.8 / len(per)
    for i, (policy, values) in enumerate(per.items()):
        items = [(v, values[v]) for v in order if v in values]
        x = np.array([order.index(v) for v, _ in items]) + (i - (len(per) - 1) / 2) * width
        err = _rate_err([s for _, s in items])
        ax.bar(x, [s["sr"] for _, s in items], width, yerr=err, capsize=3, label=policy)
    ax.set_xticks(range(len(order)), order, rotation=30, ha="right")
    ax.set(ylabel="success rate", ylim=(0, 1.05), title=title)
    ax.legend()
    _save(fig, path)


def plot_table_texture(layouts: Layouts, path: Path) -> None:
    """SR per table texture, Clopper–Pearson 95 % intervals."""
    from roboview.variation.factors import FACTORS

    _bars(
        layouts, "table_texture", path, "Success rate by table texture", list(FACTORS["table_texture"].values)
    )


def _dose_response(layouts: Layouts, split: str, path: Path, xlabel: str, title: str) -> None:
    fig, ax = plt.subplots(figsize=(6, 4), layout="constrained")
    for i, (policy, values) in enumerate(_per_value(layouts, split).items()):
        items = sorted(values.items(), key=lambda kv: float(kv[0]))
        x = np.array([float(v) for v, _ in items])
        sr = np.array([s["sr"] for _, s in items])
        n = np.array([s["n_episodes"] for _, s in items], dtype=float)
        err = _rate_err([s for _, s in items])
        line = ax.errorbar(
            x, sr, yerr=err, marker=_MARKERS[i % len(_MARKERS)], ls="none", capsize=3, label=policy
        )
        trend = logistic_trend(x, np.round(sr * n), n)
        if trend is not None:
            fitted, slope, p = trend
            ax.plot(
                np.linspace(x.min(), x.max(), 50),
                fitted,
                color=line[0].get_color(),
                label=f"{policy}: logistic trend, slope {slope:+.2f}/unit, p {p:.2g}",
            )
    ax.set(xlabel=xlabel, ylabel="success rate", ylim=(-0.05, 1.05), title=title)
    ax.legend(fontsize=8)
    _save(fig, path)


def plot_distractors(layouts: Layouts, path: Path) -> None:
    """Dose-response: SR against the number of distractors, with a fitted logistic trend."""
    _dose_response(
        layouts, "distractors", path, "distractors on the table", "Success rate vs distractor count"
    )


def plot_object_size(layouts: Layouts, path: Path) -> None:
    """SR against the object's scale, with a fitted logistic trend."""
    _dose_response(layouts, "object_size", path, "object scale", "Success rate vs object size")


# file name → (split it needs, section of the layout holding it, drawing function)
PLOTS: dict[str, tuple[str, str, Callable[[Layouts, Path], None]]] = {
    "sr_by_color_category.png": ("color", "splits", plot_color_categories),
    "sr_vs_color_lab.png": ("color", "splits", plot_color_lab),
    "sr_camera_pose.png": ("camera_pose", "splits", plot_camera_pose),
    "sr_camera_euler.png": ("camera_euler", "splits", plot_camera_euler),
    "sr_dist_scale.png": ("dist_scale", "splits", plot_dist_scale),
    "sr_color_x_camera_pose.png": ("color_x_camera_pose", "interactions", plot_color_x_camera_pose),
    "sr_lighting.png": ("lighting", "splits", plot_lighting),
    "sr_table_texture.png": ("table_texture", "splits", plot_table_texture),
    "sr_distractors.png": ("distractors", "splits", plot_distractors),
    "sr_object_size.png": ("object_size", "splits", plot_object_size),
    # A forest plot per visual factor of the registry, in its order (one registered later: make_plots).
    **{f"forest_{split}.png": (split, "splits", plot_forest(split)) for split in visual_factors()},
}


def _task_view(layouts: Layouts, task: str) -> Layouts:
    """The layouts with only `task`'s splits, under their bare names (push_color → color), so every figure
    drawn for the default task is drawn the same way for another."""
    view: Layouts = {}
    for policy, layout in layouts.items():
        view[policy] = dict(layout)
        for key in ("splits", "interactions"):
            view[policy][key] = {
                split_task(s)[1]: v for s, v in layout.get(key, {}).items() if split_task(s)[0] == task
            }
    return view


def make_plots(layouts: Layouts, output_dir: Path) -> dict[str, str | None]:
    """Draw every figure whose split is present, per task (another task's files are prefixed with its
    name: push_sr_distractors.png); file name → None if written, else the reason."""
    outcome: dict[str, str | None] = {}
    tasks = sorted(
        {
            split_task(s)[0]
            for layout in layouts.values()
            for key in ("splits", "interactions")
            for s in layout.get(key, {})
        }
        - {DEFAULT_TASK}
    )
    for task in [DEFAULT_TASK, *tasks]:
        view, prefix = _task_view(layouts, task), "" if task == DEFAULT_TASK else f"{task}_"
        for name, (split, key, draw) in PLOTS.items():
            if not any(split in layout[key] for layout in view.values()):
                if not prefix:
                    outcome[name] = f"no policy has the {split} split"
                continue
            draw(view, output_dir / f"{prefix}{name}")
            outcome[f"{prefix}{name}"] = None
        # A factor without figures of its own (a registered extension) still gets its forest plot.
        known = {split for split, _, _ in PLOTS.values()}
        for split in sorted({s for layout in view.values() for s in layout["splits"]} - known):
            name = f"{prefix}forest_{split}.png"
            plot_forest(split)(view, output_dir / name)
            outcome[name] = None
    # A task analysis draws its own figures (`analysis_<name>.png`), from every policy's result.
    from roboview.eval.reporting.decomposition import plot
    from roboview.tasks.base import analysis_designs

    for key, design in analysis_designs().items():
        ran = {
            p: layout["analyses"][key] for p, layout in layouts.items() if key in layout.get("analyses", {})
        }
        if ran:
            outcome |= plot(ran, output_dir, design)
    return outcome

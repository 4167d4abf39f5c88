"""Time-series figures from result directories, and what every figure of the reports shares: axis
labels from names, a title wrapped to its figure, one legend below the panels (matplotlib, imported
only by the functions that draw)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from geometries.errors import InputError
from edem.resultdir import read_result_dir

DERIVED = {"disp_norm_mm": ("disp_x_mm", "disp_y_mm", "disp_z_mm")}

#: unit suffixes of column and metric names (longest first) and how an axis shows them
UNIT_SUFFIXES = (("_percent", "%"), ("_nmm", "N mm"), ("_mm2", "mm²"), ("_mpa", "MPa"), ("_deg", "deg"), ("_rad", "rad"), ("_mm", "mm"), ("_n", "N"), ("_s", "s"))
#: name prefixes of a campaign's per-side metrics (verification.campaign_model.METRICS)
SIDE_PREFIXES = (("a_at_b_", "a at b's time points"), ("a_", "side a"), ("b_", "side b"))
#: words a name does not spell
WORDS = {"poissons": "Poisson's", "disp": "displacement", "l2": "L2", "cop": "centre of pressure", "edem": "EDEM", "dem": "DEM", "fe": "FE"}


def axis_label(name: str, *, magnitude: bool = False) -> str:
    """Words with units for a column, metric or parameter name: "a_peak_pressure_mpa" -> "peak
    pressure, side a (MPa)", "poissons_ratio" -> "Poisson's ratio", "contact_area_rel_error" ->
    "contact area: relative error (a - b)/|b|" (``magnitude``: its absolute value, for a log axis;
    the L2 error is a norm either way)."""
    side = ""
    for prefix, words in SIDE_PREFIXES:
        if name.startswith(prefix):
            name, side = name[len(prefix):], words
            break
    if name.endswith("_rel_error"):
        quantity = " ".join(WORDS.get(w, w) for w in name[: -len("_rel_error")].split("_"))
        if quantity.startswith("pressure L2"):
            return "pressure field: L2 relative error"
        return f"{quantity}: |relative error|" if magnitude else f"{quantity}: relative error (a − b)/|b|"
    unit = ""
    for suffix, words in UNIT_SUFFIXES:
        if name.endswith(suffix):
            name, unit = name[: -len(suffix)], words
            break
    text = " ".join(WORDS.get(w, w) for w in name.split("_"))
    if side:
        text += f", {side}"
    return f"{text} ({unit})" if unit else text


#: characters of a 10 pt title per inch of figure width (about 0.55 em a character, with a margin)
TITLE_CHARS_PER_INCH = 12


def fit_title(fig: Any, title: str, fontsize: float = 10) -> None:
    """The figure's title, wrapped to its width so that no line runs past the figure's edges."""
    width = max(20, int(fig.get_figwidth() * TITLE_CHARS_PER_INCH * 10 / fontsize))
    fig.suptitle(textwrap.fill(title, width=width, break_on_hyphens=False), fontsize=fontsize)


def figure_legend(fig: Any, axes: Any) -> None:
    """One legend for every panel's labelled lines (each label once), below the panels: it covers no data."""
    entries: dict[str, Any] = {}
    for ax in np.ravel(axes):
        for handle, label in zip(*ax.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    if entries:
        columns = max(1, min(len(entries), int(fig.get_figwidth() // 2.6)))
        fig.legend(list(entries.values()), list(entries), loc="outside lower center", ncol=columns, fontsize=8)


def read_timeseries(result_dir: str | Path) -> dict[str, np.ndarray]:
    """Columns of a result directory's timeseries.csv as float arrays, plus the derived
    :data:`DERIVED` columns (``disp_norm_mm``); the directory must verify against its manifest
    (:func:`edem.resultdir.read_result_dir`)."""
    columns = dict(read_result_dir(result_dir).timeseries)
    for name, parts in DERIVED.items():
        if all(p in columns for p in parts):
            columns[name] = np.sqrt(sum(columns[p] ** 2 for p in parts))
    return columns


def default_plot_path(result_dirs: list[str | Path], column: str) -> Path:
    """Where `edem plot` writes without --out: beside (not inside: a result directory is sealed by
    its manifest) the first result directory, ``<dir>-<column>.png`` for one directory,
    ``<dir>-vs-<other dirs>-<column>.png`` for several."""
    names = "-vs-".join(Path(d).resolve().name for d in result_dirs)
    return Path(result_dirs[0]).resolve().parent / f"{names}-{column}.png"


def plot_timeseries(result_dirs: list[str | Path], column: str, out_png: str | Path | None = None, labels: list[str] | None = None) -> Path:
    """One curve of ``column`` against time per result directory, on one figure (PNG at ``out_png``,
    default :func:`default_plot_path`). A directory with a single time point is drawn as a marked
    point (a line through one point would be invisible)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2), constrained_layout=True)
    for i, directory in enumerate(result_dirs):
        series = read_timeseries(directory)
        if column not in series:
            raise InputError(f"no column '{column}'", file=Path(directory) / "timeseries.csv", key="--column", expected="one of " + ", ".join(series))
        label = labels[i] if labels and i < len(labels) else _default_label(Path(directory))
        single = len(series["time_s"]) == 1
        ax.plot(series["time_s"], series[column], "o" if single else "-", markersize=8, label=label + (" (one time point)" if single else ""))
    ax.set_xlabel("time (s)")
    ax.set_ylabel(axis_label(column))
    ax.grid(alpha=0.3)
    figure_legend(fig, ax)
    out = Path(out_png) if out_png else default_plot_path(result_dirs, column)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=150)
    plt.close(fig)
    return out


def _default_label(directory: Path) -> str:
    try:
        summary = read_result_dir(directory).summary
        return f"{summary['scene']} ({summary['method']})"
    except (InputError, KeyError):
        return directory.name

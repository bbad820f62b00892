"""``laneshift experiment curves``: the validation curves of published networks, a panel per published
agent (the mean over its seeds with a 95 % bootstrap band over seeds), greedy survival and achievement
against env steps. It reads only the JSON that ``experiment protocol --publish`` writes beside each
network (``<dir>/<name>-seed<N>-final.json``: its ``validation`` curve), so the figure under
docs/RESULTS.md's opening tables is drawn again from a fresh clone, without the run directories.

    laneshift experiment curves "straight: imitation fading to 0=straight-imfade-dqfd-bc-alongside-safe-shield" \\
        "merge: copy then hold=merge-copy-hold-dqfd-bc-alongside-gaps-safe-shield" --out docs/img/curves-shield.png

Room: the tools (studies). May import: anything in laneshift, numpy, matplotlib.
"""

from __future__ import annotations

import argparse
import glob
import json
import re
from pathlib import Path

from laneshift.config import ConfigError
from laneshift.progress import write
from laneshift.tools.studies.plots import draw_mean_band, evaluations_on_grid
from laneshift.tools.studies.protocol_validation import VALIDATION_SEED

#: A published network's provenance file: ``<name>-seed<N>-final.json``.
SEED_FILE = re.compile(r"-seed(\d+)-final\.json$")


def agent_arg(text: str) -> tuple[str, str]:
    """``LABEL=NAME`` or ``NAME`` (the label is then the name): (label, name)."""
    label, _, name = text.rpartition("=")
    if not name:
        raise argparse.ArgumentTypeError(f"LABEL=NAME or NAME, got {text!r}")
    return (label or name), name


def published_curves(directory: Path, name: str) -> dict[int, list[dict]]:
    """{seed: validation curve} of the networks published as ``<name>-seed<N>-final`` in ``directory``
    (ConfigError naming what is missing: no such network, or one published without a curve)."""
    curves = {}
    for path in sorted(directory.glob(f"{glob.escape(name)}-seed*-final.json")):
        match = SEED_FILE.search(path.name)
        if match is None or path.name[:match.start()] != name:
            continue  # the glob's * took more than a seed: <name>-seed1-x-seed0-final.json is another name's
        try:
            curve = json.loads(path.read_text())["validation"]["curve"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ConfigError(f"{path}: no validation curve in it ({type(exc).__name__}: {exc})") from None
        curves[int(match.group(1))] = curve
    if not curves:
        raise ConfigError(f"{name}: no network published as {directory}/{name}-seed<N>-final.json")
    return curves


def plot_published(directory: Path, agents: list[tuple[str, str]], out: Path, columns: int = 3) -> Path:
    """The figure ``out``: a panel per agent ((label, published name) each; ``columns`` panels a row),
    greedy survival and achievement against env steps, the mean over its seeds with a 95 % bootstrap
    band over seeds (``plots.evaluations_on_grid``). Every curve is read before anything is drawn;
    ConfigError when a label is named twice or an agent's seeds share no two evaluations."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    labels = [label for label, _ in agents]
    if len(set(labels)) != len(labels):
        raise ConfigError(f"a label is named twice in {', '.join(labels)}")
    drawn = {}
    for label, name in agents:
        runs = list(published_curves(directory, name).values())
        rates = {field: evaluations_on_grid(runs, field) for field in ("survival_rate", "achievement_rate")}
        if len(rates["achievement_rate"]["x"]) < 2:
            raise ConfigError(f"{label}: its seeds share no two validation evaluations to draw")
        drawn[label] = (len(runs), sorted({e["episodes"] for c in runs for e in c}), rates)
    rows = -(-len(drawn) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4 * columns, 3.2 * rows), squeeze=False)
    # The panels share a y range from the lowest band down, so a reader compares heights across them.
    low = min(float(r[f]["lo"].min()) for _, _, r in drawn.values() for f in r)
    for ax, (label, (seeds, episodes, rates)) in zip(axes.flat, drawn.items()):
        for c, color, what in zip(rates.values(), ("C0", "C1"), ("survival", "achievement")):
            draw_mean_band(ax, c, color, what)
        ax.set_title(f"{label}\n({seeds} seed{'s' if seeds > 1 else ''}; {'/'.join(map(str, episodes))} episodes)",
                     fontsize=9)
        ax.set_ylim(max(0.0, 5 * (low // 5) - 5), 101)
        ax.set_xlabel("env steps", fontsize=8)
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 1000:,.0f}k"))
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
    for ax in list(axes.flat)[len(drawn):]:
        ax.set_visible(False)
    axes.flat[0].set_ylabel("greedy rate (%)", fontsize=8)
    axes.flat[0].legend(fontsize=8, loc="lower right")
    # The protocol's runs validate on its validation episodes (train.validation_seed), the same every time.
    fig.suptitle(f"validation evaluations during training (episode seeds {VALIDATION_SEED:,}+, the same every time): "
                 "mean over seeds, 95 % bootstrap band over seeds", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    write(f"curves: {out} ({len(drawn)} agents)")
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("curves", help="the validation curves of published networks (results/checkpoints), "
                                             "a panel per agent: mean and band over its seeds")
    p.add_argument("agents", nargs="+", type=agent_arg, metavar="LABEL=NAME",
                   help="a published name (<name>-seed<N>-final.json in --published), with the legend's label")
    p.add_argument("--published", type=Path, default=Path("results/checkpoints"), metavar="DIR",
                   help="where the networks were published (default: results/checkpoints)")
    p.add_argument("--out", type=Path, required=True, metavar="PNG", help="the figure's file")
    p.set_defaults(func=lambda a: (plot_published(a.published, a.agents, a.out), 0)[1])

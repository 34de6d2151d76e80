"""`langpref demo` / `make demo`: the pipeline at small size on Meta-World, ending with what it made.

Each stage is a library call (the same ones the CLI commands make); the demo only chooses small sizes and prints.
"""

from __future__ import annotations

import json
import time
from pathlib import Path


def _banner(text: str) -> None:
    print(f"\n== {text}", flush=True)


def run_demo(out: Path, workers: int | None = None, num_trajectories: int = 60) -> dict:
    from langpref.dataset.generate import GenerateConfig, generate
    from langpref.dataset.inspect import describe, format_description
    from langpref.envs.render import render_trajectory

    start = time.time()
    out = Path(out)
    data = out / "data_metaworld"
    made: dict = {}

    _banner(f"1. Generating {num_trajectories} Meta-World button-press trajectories (T = 500) in the simulator")
    if (data / "meta.json").exists():
        print(f"   reusing {data} (delete it to regenerate)")
    else:
        generate(GenerateConfig(env="metaworld", out=data, num_trajectories=num_trajectories, workers=workers,
                                force=True))
    made["dataset"] = str(data)

    _banner("2. Inspecting the dataset: feature ranges and how independent the features are")
    description = describe(data)
    print(format_description(description))
    (out / "inspect.json").write_text(json.dumps(description, indent=2))

    _banner("3. Rendering one successful and one failed trajectory to video (offscreen, EGL)")
    from langpref.dataset.storage import load_dataset

    ds = load_dataset(data)
    for label, idx in (("success", int(ds.success.argmax())), ("failure", int((~ds.success).argmax()))):
        video = render_trajectory(data, idx, out / f"trajectory_{idx}_{label}.mp4", stride=2, fps=20)
        made[f"video_{label}"] = str(video)
        print(f"   {label}: trajectory {idx} -> {video}")

    _banner(f"Done in {time.time() - start:.0f} s. What the demo made:")
    for key, value in made.items():
        print(f"   {key:<16} {value}")
    print(f"   {'inspect':<16} {out / 'inspect.json'}")
    print(
        "\nGo further:\n"
        "   langpref generate --env metaworld --out data/metaworld     # the paper's 324 trajectories (~1-2 min)\n"
        "   langpref generate --env robosuite --out data/robosuite     # the paper's 448 (Jaco, cube and bottle)\n"
        "   langpref inspect data/metaworld --json\n"
        "   langpref render data/metaworld --index 0 --out traj0.webm"
    )
    return made

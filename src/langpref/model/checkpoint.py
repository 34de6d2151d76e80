"""A trained latent-space model on disk: one directory, self-describing, checked when loaded.

    MODEL/
      config.json            format version, the full TrainConfig, the architecture (with what the trajectory
                             encoder sees: state, images or images+state), the language model's original name and
                             identity (registered name, architecture, weights checksum: `lang_model_info`), the
                             data it was trained on (env, features, observation layout, action size, dataset schema
                             version, tie thresholds, frame size and stride), normalisation stats, history,
                             results, and the size and sha256 of every other file
      encoders.safetensors   trajectory encoder (with its normalisation buffers and, seeing images, its frame CNN),
                             language head, meaning prototypes
      language_model/        the fine-tuned transformer and its tokenizer (save_pretrained); absent when the
                             transformer was frozen, which then loads again from its original name
      training_curve.png     loss and accuracy per epoch (written by training)

A checkpoint is written into a temporary sibling directory and renamed into place, so a crash never leaves half a
model, and an existing directory is replaced only with `force`.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from langpref import __version__
from langpref.errors import LangprefError
from langpref.language.lab_default import AUTO, lang_model_for
from langpref.language.loading import load_transformer
from langpref.language.transformer import save_transformer
from langpref.model.config import ModelConfig
from langpref.model.encoders import LanguageEncoder, TrajectoryEncoder, step_input_dim
from langpref.model.inputs import numeric_dim, sees_images
from langpref.model.latent import DataInfo, LatentModel
from langpref.model.vision import ImageTrajectoryEncoder
from langpref.tasks import register_task
from langpref.tasks.taskfile import load_stored_task

FORMAT = "langpref-latent-model"
FORMAT_VERSION = 1
WEIGHTS = "encoders.safetensors"
LM_DIR = "language_model"
CONFIG = "config.json"


def build_model(model_cfg: ModelConfig, info: DataInfo, mean, std, lang_source: str | None = None) -> LatentModel:
    """A fresh model (random trajectory encoder and head, pretrained transformer from `lang_source` or the name).
    `model_cfg.observations` says what the trajectory encoder sees (None, from before the option: state)."""
    if model_cfg.lang_model == AUTO:  # a config made without `train`'s resolution (`TrainConfig.resolved`)
        model_cfg = replace(model_cfg, lang_model=lang_model_for(None, info.env))
    tokenizer, transformer = load_transformer(lang_source or model_cfg.lang_model)
    observations, deltas = model_cfg.observations or "state", model_cfg.observation_deltas
    magnitudes = model_cfg.delta_magnitudes
    traj: TrajectoryEncoder | ImageTrajectoryEncoder
    if not sees_images(observations):
        traj = TrajectoryEncoder(
            step_input_dim(info.obs_dim, info.action_dim, deltas, magnitudes),
            model_cfg.traj_hidden,
            model_cfg.latent_dim,
            mean,
            std,
            observation_deltas=deltas,
            delta_magnitudes=magnitudes,
        )
    else:
        traj = ImageTrajectoryEncoder(
            numeric_dim(observations, info.obs_dim, info.action_dim, deltas, magnitudes),
            model_cfg.traj_hidden,
            model_cfg.latent_dim,
            observations,
            model_cfg.frame_channels,
            model_cfg.frame_features,
            mean,
            std,
            observation_deltas=deltas,
            frame_shift=model_cfg.frame_shift,
            delta_magnitudes=magnitudes,
        )
    lang = LanguageEncoder(tokenizer, transformer, model_cfg.latent_dim, model_cfg.max_length)
    return LatentModel(traj, lang, info, model_cfg.lang_model, negation=model_cfg.negation)


def _own_state(model: LatentModel) -> dict[str, torch.Tensor]:
    """Every tensor of the model except the transformer's (saved apart, and only when fine-tuned)."""
    return {
        k: v.detach().cpu().contiguous() for k, v in model.state_dict().items() if not k.startswith("lang.transformer.")
    }


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _config_record(model: LatentModel, model_cfg: ModelConfig, lang_finetuned: bool) -> dict[str, Any]:
    """The head of a checkpoint's config.json: its format, the architecture, the language model and the data it
    was trained on (what `load_model` needs to rebuild it)."""
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "langpref_version": __version__,
        "model": {
            **model_cfg.__dict__,
            "traj_hidden": list(model_cfg.traj_hidden),
            "frame_channels": list(model_cfg.frame_channels),
            "lang_hidden": model.lang.hidden_size,
            "negation": model.negation,  # the model's own setting, whatever the config said
        },
        "lang_model": model.lang_model_name,
        "lang_model_info": lang_model_info(model.lang_model_name, model.lang.transformer),
        "lang_finetuned": lang_finetuned,
        "data": model.info.to_dict(),
        "normalisation": {"mean": model.traj.mean.cpu().tolist(), "std": model.traj.std.cpu().tolist()},
        "meanings": [f"{f}/{d}" for f, d in model.meanings],
    }


def _swap_in(tmp: Path, out: Path) -> None:
    """Make the finished checkpoint `tmp` readable by all and put it in place of `out` (an old `out` is moved
    aside first and removed only after, so a failure never leaves neither)."""
    for p in tmp.rglob("*"):  # some writers create 0600 files; a model is meant to be shared
        p.chmod(0o755 if p.is_dir() else 0o644)
    tmp.chmod(0o755)
    if out.exists():
        old = out.parent / f".{out.name}.old-{os.getpid()}"
        out.rename(old)
        tmp.rename(out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(out)


def save_model(
    model: LatentModel,
    out: str | Path,
    *,
    model_cfg: ModelConfig,
    lang_finetuned: bool,
    train_config: dict[str, Any] | None = None,
    history: list[dict] | None = None,
    results: dict[str, Any] | None = None,
    force: bool = False,
    extra_files: dict[str, Path] | None = None,
) -> Path:
    """Write `model` as a checkpoint directory `out`; refuses an existing `out` unless `force`."""
    from safetensors.torch import save_file

    out = Path(out)
    if out.exists() and not force:
        raise LangprefError(f"{out} already exists; pass --force to overwrite it or choose another --out")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    try:
        save_file(_own_state(model), str(tmp / WEIGHTS))
        if lang_finetuned:
            save_transformer(model.lang.tokenizer, model.lang.transformer, tmp / LM_DIR)
        for name, src in (extra_files or {}).items():
            shutil.copyfile(src, tmp / name)
        files = {
            p.relative_to(tmp).as_posix(): {"bytes": p.stat().st_size, "sha256": _sha256(p)}
            for p in sorted(tmp.rglob("*"))
            if p.is_file()
        }
        config = {
            **_config_record(model, model_cfg, lang_finetuned),
            "train_config": train_config or {},
            "history": history or [],
            "results": results or {},
            "files": files,
        }
        (tmp / CONFIG).write_text(json.dumps(config, indent=2) + "\n")
        _swap_in(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out


def lang_model_info(name: str, transformer: torch.nn.Module) -> dict[str, Any]:
    """What names the pretrained language model a checkpoint was built on: its registered name (or the hub name or
    path as given), the architecture, and a checksum of its weights (the pretrained ones, for a frozen model that
    is loaded again from its name); for a language model langpref built (`comparative`), the model it started from
    (`built_from`) and its build's settings and corpus."""
    from langpref.language.models import built_record, canonical_name
    from langpref.model.encoders import transformer_state_fingerprint

    cfg = transformer.config
    info = {
        "name": canonical_name(name),
        "model_type": getattr(cfg, "model_type", None),
        "hidden_size": int(getattr(cfg, "hidden_size", getattr(cfg, "d_model", 0))),
        "num_layers": int(getattr(cfg, "num_hidden_layers", getattr(cfg, "num_layers", 0))),
        "vocab_size": int(getattr(cfg, "vocab_size", 0)),
        "weights_sum": transformer_state_fingerprint(transformer),
    }
    record = built_record(name)
    if record is not None:  # a model langpref built: what it started from, on which corpus, how
        info["built_from"] = record.get("built_from")
        info["build"] = {k: record.get(k) for k in ("config", "corpus", "objective")}
    return info


def check_lang_model(path: Path, cfg: dict[str, Any], asked: str | None) -> None:
    """Refuse to load a checkpoint with a language model other than the one it names (`asked`, as a command was
    given it), in one line naming both."""
    if asked is None:
        return
    from langpref.language.models import canonical_name

    own = (cfg.get("lang_model_info") or {}).get("name") or canonical_name(cfg["lang_model"])
    if canonical_name(asked) != own:
        raise LangprefError(
            f"model {path} was trained with language model {own!r}; it cannot be loaded with {asked!r} (a model "
            "reads sentences only with its own language model: drop --lang-model or train a model with it)"
        )


def _check_reloaded(path: Path, cfg: dict[str, Any], transformer: torch.nn.Module) -> None:
    """A frozen language model is loaded again from its name: refuse when that name now gives another model."""
    saved = cfg.get("lang_model_info")
    if not saved or cfg.get("lang_finetuned"):
        return
    now = lang_model_info(cfg["lang_model"], transformer)
    keys = ("model_type", "hidden_size", "num_layers", "vocab_size")
    same = all(saved.get(k) == now[k] for k in keys) and abs(saved["weights_sum"] - now["weights_sum"]) <= 1e-6 * max(
        1.0, abs(saved["weights_sum"])
    )
    if not same:
        raise LangprefError(
            f"model {path} was trained with language model {saved['name']!r}, but {cfg['lang_model']!r} now loads a "
            "different model (other weights or architecture); install the one it was trained with or retrain"
        )


def read_config(path: str | Path) -> dict[str, Any]:
    """The checked config.json of a checkpoint directory."""
    path = Path(path)
    if not path.exists():
        raise LangprefError(f"model {path} does not exist; train one with `langpref train --data DIR --out {path}`")
    cfg_path = path / CONFIG
    if not path.is_dir() or not cfg_path.is_file():
        raise LangprefError(f"{path} is not a langpref model (no {CONFIG}); train one with `langpref train`")
    try:
        cfg = json.loads(cfg_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise LangprefError(f"{cfg_path} is corrupt ({exc.__class__.__name__}); retrain the model") from None
    if not isinstance(cfg, dict) or cfg.get("format") != FORMAT:
        raise LangprefError(f"{cfg_path} is not a langpref latent-model config; retrain the model")
    if cfg.get("format_version") != FORMAT_VERSION:
        raise LangprefError(
            f"{path} has model format version {cfg.get('format_version')!r}, this langpref reads "
            f"{FORMAT_VERSION}; retrain the model"
        )
    for key in ("model", "data", "files", "lang_model"):
        if key not in cfg:
            raise LangprefError(f"{cfg_path} lacks {key!r}; retrain the model")
    return cfg


def _check_files(path: Path, files: dict[str, dict[str, Any]]) -> None:
    for name, facts in files.items():
        f = path / name
        if not f.is_file():
            raise LangprefError(f"model {path} is incomplete: {name} is missing; retrain the model")
        size = f.stat().st_size
        if size != facts.get("bytes"):
            raise LangprefError(
                f"{f} is truncated or altered ({size} bytes, expected {facts.get('bytes')}); retrain the model"
            )
        if _sha256(f) != facts.get("sha256"):
            raise LangprefError(f"{f} is corrupt (checksum mismatch); retrain the model")


def _description(path: Path, cfg: dict[str, Any]) -> tuple[ModelConfig, DataInfo]:
    """The architecture and the data facts of a checkpoint's config.json; fields added since an older checkpoint
    was written take the value that reproduces it (or, for `negation`, a reading setting, today's default)."""
    try:
        mc = dict(cfg["model"])
        mc.pop("lang_hidden", None)
        mc.setdefault("observation_deltas", False)  # checkpoints from before the option: (observation, action)
        mc.setdefault("delta_magnitudes", False)  # checkpoints from before the option: no |change| inputs
        mc.setdefault("observations", "state")  # checkpoints from before image observations
        mc["traj_hidden"] = tuple(mc["traj_hidden"])
        if "frame_channels" in mc:
            mc["frame_channels"] = tuple(mc["frame_channels"])
        return ModelConfig(**mc), DataInfo(**cfg["data"])
    except (TypeError, KeyError) as exc:
        raise LangprefError(f"{path / CONFIG} is not a valid model description ({exc}); retrain the model") from None


def load_model(
    path: str | Path,
    device: str | torch.device = "cpu",
    dataset=None,
    lang_model: str | None = None,
    negation: bool | None = None,
) -> LatentModel:
    """Load a checkpoint directory; with `dataset`, also check the model fits it (env, observation layout); with
    `lang_model`, refuse a checkpoint that names another language model. A frozen language model, loaded again from
    its name, must be the one the checkpoint was trained with (its architecture and weights checksum). `negation`
    overrides the checkpoint's reading of negated requests (`ModelConfig.negation`; a checkpoint from before the
    setting reads with its default); None keeps the checkpoint's."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    path = Path(path)
    cfg = read_config(path)
    check_lang_model(path, cfg, lang_model)
    stored = load_stored_task(path)  # a model of a recorded task carries it: its task is known wherever it goes
    if stored is not None:
        register_task(stored)
    if WEIGHTS not in cfg["files"]:
        raise LangprefError(f"{path / CONFIG} lists no {WEIGHTS}; retrain the model")
    _check_files(path, cfg["files"])
    try:
        state = load_file(str(path / WEIGHTS))
    except (SafetensorError, OSError, ValueError) as exc:
        raise LangprefError(f"{path / WEIGHTS} is unreadable ({type(exc).__name__}); retrain the model") from None
    model_cfg, info = _description(path, cfg)
    lang_source = str(path / LM_DIR) if cfg.get("lang_finetuned") else cfg["lang_model"]
    if cfg.get("lang_finetuned") and not (path / LM_DIR).is_dir():
        raise LangprefError(f"model {path} is incomplete: {LM_DIR}/ is missing; retrain the model")
    model = build_model(model_cfg, info, None, None, lang_source=lang_source)
    _check_reloaded(path, cfg, model.lang.transformer)
    model.lang_model_name = cfg["lang_model"]
    try:
        missing, unexpected = model.load_state_dict(state, strict=False)
    except RuntimeError as exc:
        msg = str(exc).strip().splitlines()[-1].strip()[:160]
        raise LangprefError(
            f"{path / WEIGHTS} does not fit the architecture in {CONFIG} ({msg}); retrain the model"
        ) from None
    missing = [k for k in missing if not k.startswith("lang.transformer.")]
    if missing or unexpected:
        raise LangprefError(
            f"{path / WEIGHTS} does not fit the architecture in {CONFIG} (missing "
            f"{missing[:3]}, unexpected {unexpected[:3]}); retrain the model"
        )
    model.config = cfg  # the whole config.json, for reports
    if negation is not None:
        model.negation = negation
    model.to(device)
    model.eval()
    if dataset is not None:
        model.check_dataset(dataset)
    return model

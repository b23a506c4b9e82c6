"""Which avatar models exist, by name (avatar.json's "model", `train --model`), and avatars from their folders.
Adding a model: its folder under models/avatars/, one line in AVATARS and its name in ModelName
(models/avatars/names.py: `train --model`'s choices, read without torch)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from models.avatars.base import Avatar
from models.avatars.card import AvatarCard, card_of
from models.avatars.checkpoint import CheckpointError, load_checkpoint, read_meta
from models.avatars.codynerf.avatar import CoDyNeRFAvatar
from models.avatars.nerface.avatar import NerfaceAvatar
from models.avatars.primitives.avatar import PrimitivesAvatar
from models.avatars.prior.avatar import PriorAvatar
from models.avatars.quality import load_presets
from models.avatars.whole.avatar import WholeHeadAvatar
from models.device import device_of
from models.head.sources import head_kind, load_head

AVATARS: dict[str, type[Avatar]] = {cls.name: cls for cls in (
    CoDyNeRFAvatar,
    NerfaceAvatar,
    PrimitivesAvatar,
    PriorAvatar,
    WholeHeadAvatar,
)}
DEFAULT_MODEL = "codynerf"
VIDEO_MODEL = "primitives"
"""What `train` makes of a tracked video when no model is named: on the three shared clips (256 px, 30 minutes,
the last 10% held out) the primitives reach 25 dB on each (25.6-26.4 on d3 and talking_hdtf, where CoDyNeRF gives
24.4-25.3; 31.3-31.5 on d19 against CoDyNeRF's 32.9-33.3), and a 256 px frame renders in 0.25-0.36 s against
CoDyNeRF's 1.0-5.4 s (README, Real people)."""


SHIPPED_PRIOR = Path(__file__).resolve().parents[2] / "resources" / "prior"
"""The universal prior that ships (`scripts/make_prior.sh` rebuilds it), for the head model it was trained on."""
VIDEO_START = "whole"
"""How `train` starts a tracked video's avatar when neither a model nor a prior is named: "scratch", VIDEO_MODEL
from nothing; "prior", personalising the universal prior (of any head model: load_prior); "whole", both (a whole-head
avatar, models/avatars/whole/: VIDEO_MODEL from scratch where the video saw the head, the prior personalised for
3 of every 30 minutes where it did not), where SHIPPED_PRIOR is there (else from scratch).
Measured (docs/results.md, Beyond the captured views): on two real clips held out by view, 30 minutes from scratch
gave 31.67 and 35.26 dB on the furthest turns where personalising the prior gave 28.55 and 31.05 (3 minutes) or
29.47 and 33.66 (30 minutes: its whole head lost); only the prior has a head beyond the views (+5.1 to +8.6 dB
behind and beside on a synthetic person with hair). The whole head renders the video's own views as the scratch
avatar does, and the rest as the prior."""


def training_start(capture_head: str | None, tracked: bool, model: str | None, from_scratch: bool,
                   prior: Path | None) -> tuple[str, Path | None, str]:
    """How `train` starts, the prior it personalises, and the line that says why: "scratch" (`model` from nothing,
    no prior), "prior" (the prior personalised) or "whole" (both: WholeHeadAvatar). A prior is personalised where
    one is asked for (`--model prior` or `--model whole`, or `--prior FOLDER` alone: personalised; an error where
    it is not a universal prior; FOLDER, else SHIPPED_PRIOR, of whichever head model: load_prior) or, for a tracked
    video with neither a model nor a prior named, as VIDEO_START says where SHIPPED_PRIOR is there."""
    scratch = "from scratch" + (" (--from-scratch)" if from_scratch else "")
    if from_scratch or model not in (None, PriorAvatar.name, WholeHeadAvatar.name):
        return "scratch", None, scratch
    asked = model is not None or prior is not None
    way = model or (PriorAvatar.name if prior is not None else VIDEO_START if tracked else "scratch")
    if way == "scratch":
        return way, None, scratch
    folder = Path(prior) if prior is not None else SHIPPED_PRIOR
    kind = head_kind(capture_head)
    try:
        meta = read_meta(folder)
    except CheckpointError as e:
        if not asked:
            return "scratch", None, f"from scratch (no universal prior: {e})"
        raise
    if meta.get("model") != PriorAvatar.name:
        what = f"a {meta.get('model')} avatar, not a universal prior"
        if not asked:
            return "scratch", None, f"from scratch ({folder} is {what})"
        raise CheckpointError(f"{folder}: is {what} (`prior-train` makes one)")
    people = len(meta.get("corpus", {}).get("identities", ())) or "its"
    prior_kind = head_kind(meta.get("head_model"))
    source = f"the universal prior {folder} ({people} people of the {prior_kind} head" + \
        (")" if prior_kind == kind else f", on the {kind} head the capture is tracked with: load_prior)")
    if way == WholeHeadAvatar.name:
        return way, folder, (f"as a whole head: {VIDEO_MODEL} from scratch where the video saw the head, and {source} "
                             "personalised for the sides and back it never showed (--from-scratch: the first "
                             "alone)")
    return way, folder, (f"from {source}: personalising it, so the sides and back the video never showed come "
                         "from the heads it has seen (--from-scratch trains from nothing)")


def load_prior(folder: str | Path, head_spec: str, device: str = "cpu") -> tuple[PriorAvatar, dict]:
    """The universal prior in `folder` for a capture tracked with the head model `head_spec`, and its avatar.json:
    as load_avatar reads it where it is of that head model; of another, the same weights on that head model's
    primitives. The prior's decoder, maps and slabs live in the primitives' chart, which is the same for every head
    model (layout.py: a spherical chart about the head's centre), so only where each primitive sits on the mesh
    (the layout's buffers) is the head model's own, made anew. Measured (docs/results.md): the built-in head's
    prior personalised for 3 minutes on d3 tracked with ICT's head, 24.15 dB held out by view, where on d3 tracked
    with the built-in head it gave 24.13."""
    meta = read_meta(folder)
    if meta.get("model") != PriorAvatar.name:
        raise CheckpointError(f"{folder}: a {meta.get('model')} avatar, not a universal prior (`prior-train` makes "
                              "one)")
    same = head_kind(meta.get("head_model")) == head_kind(head_spec)
    return load_avatar(folder, device, PriorAvatar.name, None if same else head_spec)


LAYOUT_BUFFERS = ("layout_",)
"""The primitives' buffers that say where each sits on its head model's mesh (PrimitivesAvatar.__init__)."""


def default_model(tracked: bool) -> str:
    """The model `train` makes when none is named: VIDEO_MODEL for a tracked video, else DEFAULT_MODEL."""
    return VIDEO_MODEL if tracked else DEFAULT_MODEL
BASELINE_MODEL = "nerface"
"""The dense renderer `bench` times beside the others."""


def avatar_class(name: str) -> type[Avatar]:
    try:
        return AVATARS[name]
    except KeyError:
        raise ValueError(f"unknown avatar model {name!r}: expected one of {', '.join(AVATARS)}") from None


def load_avatar(folder: str | Path, device: str = "cpu", model: str | None = None, on_head: str | None = None
                ) -> tuple[Avatar, dict]:
    """The avatar avatar.json describes (its "model"; avatars written before models had names are CoDyNeRF's)
    with its weights and presets, on `device`, in eval mode; and avatar.json. model: the one model a caller works
    with (a model's own benchmark or pictures): a CheckpointError where the folder holds another's. on_head: a head
    model's spec to place it on instead of its own (load_prior: every weight but where its primitives sit,
    LAYOUT_BUFFERS, which are made for that head; the avatar.json returned names it)."""
    ck = load_checkpoint(folder)
    meta = ck.meta if on_head is None else {**ck.meta, "head_model": on_head}
    name = meta.get("model", DEFAULT_MODEL)
    if model is not None and name != model:
        raise CheckpointError(f"{folder}: a {name} avatar, not a {model} one")
    try:
        check_meta(meta)
        head = load_head(meta["head_model"])
        cls = avatar_class(name)
        avatar = cls.from_meta(head, meta)
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(f"{Path(folder) / 'avatar.json'}: {e}") from None
    weights = ck.weights if on_head is None else {k: v for k, v in ck.weights.items()
                                                 if not k.startswith(LAYOUT_BUFFERS)}
    try:
        missing, unexpected = avatar.load_state_dict(weights, strict=on_head is None)
        if unexpected or any(not k.startswith(LAYOUT_BUFFERS) for k in missing):  # on_head: what strict would say
            raise RuntimeError(f"weights that do not fit:\n{sorted(unexpected) or sorted(missing)}")
    except RuntimeError as e:  # torch lists every mismatched tensor, one a line: the first says enough
        first = next((ln.strip() for ln in str(e).splitlines()[1:] if ln.strip()), str(e).splitlines()[0])
        raise CheckpointError(f"{Path(folder) / 'avatar.json'}: does not describe these weights ({first})") from None
    avatar.eval()
    # draft/preview/final, chosen and measured by `bench` (and where: machine, image size), else built in
    avatar.card = card_of(name, meta, head, avatar.effects, avatar.default_buffers(), avatar.inspection_buffers(),
                          *load_presets(folder))
    return avatar.to(device_of(device)), meta


def read_card(folder: str | Path) -> AvatarCard:
    """What an avatar folder says of its avatar (avatar.json, presets.json) without building it or reading its
    weights: the studio's window needs no more (its render process loads the avatar)."""
    meta = read_meta(folder)
    name = meta.get("model", DEFAULT_MODEL)
    try:
        head = load_head(meta["head_model"])
        cls = avatar_class(name)
        buffers, inspection = cls.buffer_names(meta)
        return card_of(name, meta, head, tuple(meta.get("effects", ())), buffers, inspection,
                       *load_presets(folder))
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(f"{Path(folder) / 'avatar.json'}: {e}") from None


def check_meta(meta: dict) -> None:
    """The fields every avatar.json has: ValueError naming the one that is wrong."""
    try:
        bg = np.asarray(meta["background"], np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"field background {meta['background']!r}: not an RGB colour") from None
    if bg.shape != (3,) or not np.isfinite(bg).all():
        raise ValueError(f"field background {meta['background']!r}: not an RGB colour (three finite numbers)")
    frames = meta["frames"]
    if not isinstance(frames, int) or isinstance(frames, bool) or frames < 1:
        raise ValueError(f"field frames {frames!r}: not a positive whole number")


def untrained_avatar(name: str, head_model, background: np.ndarray | None = None) -> Avatar:
    """An untrained avatar of a model with its default sizes, for one frame (timing: the weights do not change
    the work)."""
    bg = np.ones(3, np.float32) if background is None else background
    return avatar_class(name).for_capture(head_model, 1, bg, (), None).eval()

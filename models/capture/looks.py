"""What a synthetic person looks like beyond the head model's shape: hair style and colour, skin tone, eyes,
blush. A value chosen by the capture's identity seed (a corpus of many people gets many looks) or named."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from models.capture.configs import HairColorName, HairStyle

HAIR_STYLES: tuple[str, ...] = ("crop", "bob", "long")  # "none": bald, as the heads were before they had hair
#: Linear RGB albedo of each hair colour (the strands' mean; the texture varies it by about +-40%).
HAIR_COLORS: dict[str, tuple[float, float, float]] = {
    "black": (0.018, 0.015, 0.013),
    "dark_brown": (0.055, 0.033, 0.020),
    "brown": (0.13, 0.075, 0.040),
    "blond": (0.50, 0.36, 0.19),
    "auburn": (0.24, 0.075, 0.030),
    "grey": (0.36, 0.35, 0.34),
}
#: Linear RGB skin albedos, light to dark.
SKIN_TONES: tuple[tuple[float, float, float], ...] = (
    (0.84, 0.66, 0.56), (0.78, 0.57, 0.46), (0.66, 0.45, 0.34), (0.52, 0.35, 0.25), (0.40, 0.26, 0.19))
IRIS_COLORS: tuple[tuple[float, float, float], ...] = ((0.25, 0.35, 0.55), (0.35, 0.22, 0.10), (0.28, 0.40, 0.22))


@dataclass(frozen=True)
class Look:
    """One synthetic person's appearance, apart from the head's shape."""

    hair: HairStyle = "crop"
    """Hair style: crop (short, above the ears), bob (to the jaw), long (to the shoulders) or none (bald)."""
    hair_color: HairColorName = "dark_brown"
    """Colour of the hair (the brows and lashes take a darker shade of it)."""
    skin_tone: int = 1
    """Index into SKIN_TONES, light (0) to dark (4)."""
    iris: int = 1
    """Index into IRIS_COLORS: blue, brown, green."""
    blush: float = 0.5
    """Redness of cheeks and nose, 0 none to 1 strong."""
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """Per-channel scale of the skin tone (a person's own shade of it)."""
    seed: float = 0.0
    """Offset of the procedural noise (skin grain, strands): two people never share the same pores."""


#: The look of identity 0, the mean head: the shipped demo's person.
DEFAULT_LOOK = Look()


def look_for_identity(identity: int, hair: HairStyle | None = None, hair_color: HairColorName | None = None
                      ) -> Look:
    """The look an identity seed draws (0: DEFAULT_LOOK), with the hair style or colour named overriding it.

    >>> look_for_identity(0) == DEFAULT_LOOK, look_for_identity(7) == look_for_identity(7)
    (True, True)
    >>> look_for_identity(0, hair="long", hair_color="auburn").hair_color
    'auburn'
    """
    if identity == 0:
        look = DEFAULT_LOOK
    else:
        rng = np.random.default_rng([identity, 0x100C])
        colors = list(HAIR_COLORS)
        look = Look(hair=HAIR_STYLES[int(rng.integers(len(HAIR_STYLES)))],
                    hair_color=colors[int(rng.integers(len(colors)))],  # type: ignore[arg-type]
                    skin_tone=int(rng.integers(len(SKIN_TONES))),
                    iris=int(rng.integers(len(IRIS_COLORS))),
                    blush=float(rng.uniform(0.2, 0.9)),
                    tint=tuple(float(x) for x in rng.uniform(0.95, 1.05, 3)),  # type: ignore[arg-type]
                    seed=float(identity % 97) * 0.013)
    return replace(look, hair=hair or look.hair, hair_color=hair_color or look.hair_color)


def hair_albedo(look: Look) -> np.ndarray:
    return np.asarray(HAIR_COLORS[look.hair_color])


def brow_albedo(look: Look) -> np.ndarray:
    """Brows and lashes: the hair's colour, darker (grey and blond brows are usually darker than the head)."""
    return np.minimum(hair_albedo(look) * 0.7, 0.2) + 0.01


def skin_albedo(look: Look) -> np.ndarray:
    return np.asarray(SKIN_TONES[look.skin_tone]) * np.asarray(look.tint)

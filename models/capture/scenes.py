"""Lighting scenes and the head's made-up appearance for synthetic captures (docs/training.md): each scene
simulates only its effects."""

from __future__ import annotations

import math

import numpy as np

from models.capture.configs import SceneName
from models.capture.looks import IRIS_COLORS, Look, brow_albedo, hair_albedo, skin_albedo
from models.head.model import HeadModel
from render.gl.capture import Appearance, CaptureLighting

#: The effects each scene simulates (docs/training.md): ambient none, studio diffuse shading, sun all three.
SCENE_EFFECTS: dict[str, tuple[str, ...]] = {
    "ambient": (),
    "studio": ("shading",),
    "sun": ("shading", "specular", "shadows"),
}
DEFAULT_LIGHT_DEG = {"ambient": (0.0, 0.0), "studio": (35.0, 25.0), "sun": (50.0, 35.0)}
SH_BASIS = "1, y, z, x, xy, yz, 3z^2-1, xz, x^2-y^2"


def light_direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector towards the light: azimuth about +y from the face's front (+z) towards the subject's
    left (+x), elevation up from the horizon."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])


def _sh(level: float, tint: tuple[float, float, float]) -> np.ndarray:
    """Irradiance SH (basis SH_BASIS): a sky-lit room, brighter from above and in front."""
    shape = np.array([1.0, 0.22, 0.10, 0.03, 0.0, 0.03, -0.03, 0.0, 0.02])
    return (shape[:, None] * level * np.asarray(tint)[None]).astype(np.float32)


def scene_lighting(scene: SceneName, light_deg: tuple[float, float] | None = None) -> CaptureLighting:
    az, el = light_deg if light_deg is not None else DEFAULT_LIGHT_DEG[scene]
    effects = SCENE_EFFECTS[scene]
    level = {"ambient": 0.78, "studio": 0.40, "sun": 0.24}[scene]
    return CaptureLighting(
        sh=_sh(level, (1.0, 0.98, 1.02)),
        light_dir=light_direction(az, el),
        light_color=np.array({"ambient": (0.0, 0.0, 0.0), "studio": (0.62, 0.60, 0.57),
                              "sun": (0.95, 0.90, 0.80)}[scene]),
        diffuse="shading" in effects,
        specular="specular" in effects,
        shadows="shadows" in effects,
        shininess=48.0,
    )


def lighting_record(scene: SceneName, lighting: CaptureLighting, light_deg: tuple[float, float] | None) -> dict:
    """The dataset's `lighting` entry: the ground truth a model of the capture can be judged against."""
    az, el = light_deg if light_deg is not None else DEFAULT_LIGHT_DEG[scene]
    return {
        "scene": scene,
        "effects": list(SCENE_EFFECTS[scene]),
        "color_space": "linear",
        "sh_basis": SH_BASIS,
        "sh_irradiance": np.asarray(lighting.sh).tolist(),
        "key_light": None if not lighting.diffuse else {
            "direction": np.round(lighting.light_dir, 6).tolist(), "azimuth_deg": az, "elevation_deg": el,
            "color": np.asarray(lighting.light_color).tolist()},
        "specular": {"model": "blinn-phong", "shininess": lighting.shininess,
                     "map": "base 0.04, peak 0.5 on forehead and nose, 0.9 on the eyes, 0.3 on the teeth",
                     "hair": "Kajiya-Kay along the strands: 0.12 white (exponent 80) + 0.6 albedo (exponent 24, "
                             "tangent tilted 0.25 towards the normal), scaled by the strand texture"}
        if lighting.specular else None,
        "shadows": {"method": "shadow map", "size_px": lighting.shadow_map_px} if lighting.shadows else None,
        "model": "I = albedo * (SH(n) + key * max(n.l, 0) * visibility) + spec * key * max(n.h, 0)^shininess "
                 "* visibility [n.l > 0] (on hair, the Kajiya-Kay term instead); terms absent from `effects` are zero",
    }


def landmarks68(head: HeadModel, canonical: np.ndarray) -> np.ndarray | None:
    """(68,3) the iBUG landmarks on the canonical head (FLAME's 51 with a NaN jaw line), or None."""
    ids, bary = head.landmarks.as_barycentric(head.triangles)
    lm = (canonical[ids] * bary[..., None]).sum(1)
    if len(lm) == 68:
        return lm
    if len(lm) == 51:  # FLAME's static embedding: the 68 points without the jaw line
        return np.concatenate([np.full((17, 3), np.nan), lm])
    return None


def head_appearance(head: HeadModel, canonical: np.ndarray, look: Look) -> Appearance:
    """The look's colours; lips, brows, cheeks, nose and forehead placed from the landmarks."""
    skin = skin_albedo(look)
    iris = np.asarray(IRIS_COLORS[look.iris])
    lm = landmarks68(head, canonical)
    far = np.array([0.0, 0.0, -10.0])
    if lm is None:  # no landmarks: plain skin, a specular map without peaks
        return Appearance(skin, skin, skin, iris, far, np.ones(2) * 1e-3,
                          np.stack([far, far]), np.ones(2) * 1e-3, far, far + 1e-3, far, np.ones(3) * 1e-3,
                          seed=look.seed, hair_color=hair_albedo(look))
    lips = lm[48:60]
    brows = [lm[17:22], lm[22:27]]
    brow_span = [np.ptp(b[:, 0]) for b in brows]
    forehead = 0.5 * (brows[0].mean(0) + brows[1].mean(0)) + [0.0, 0.035, -0.006]
    # Cheeks: below the outer half of each eye, level with the nose's wings, a little behind them.
    cheeks = np.stack([[0.5 * (lm[a, 0] + lm[b, 0]), 0.5 * (lm[lid, 1] + lm[wing, 1]), lm[wing, 2] - 0.012]
                       for a, b, lid, wing in ((36, 37, 41, 31), (45, 44, 46, 35))])
    return Appearance(
        skin_color=skin,
        lip_color=skin * np.array([0.95, 0.55, 0.55]),
        brow_color=brow_albedo(look),
        iris_color=iris,
        lip_center=lips.mean(0),
        lip_radii=np.array([0.55 * np.ptp(lips[:, 0]), 0.6 * np.ptp(lips[:, 1])]),
        brow_centers=np.stack([b.mean(0) + [0.0, 0.002, 0.0] for b in brows]),
        brow_radii=np.array([0.5 * max(brow_span) + 0.003, 0.0055]),
        nose_top=lm[27],
        nose_tip=lm[30],
        forehead_center=forehead,
        forehead_radii=np.array([0.045, 0.022, 0.03]),
        seed=look.seed,
        hair_color=hair_albedo(look),
        cheek_centers=cheeks,
        blush=look.blush,
    )


def eye_attribute(head: HeadModel, canonical: np.ndarray) -> np.ndarray:
    """(V,4): each eyeball vertex's eyeball centre (its eye joint at rest) and 1; skin vertices 0."""
    out = np.zeros((head.num_vertices, 4), np.float32)
    joints = head.J_regressor @ canonical
    for name in ("eye_l", "eye_r"):
        if name in head.joint_names:
            j = head.joint_names.index(name)
            on = head.weights[:, j] > 0.5
            out[on, :3] = joints[j]
            out[on, 3] = 1.0
    return out

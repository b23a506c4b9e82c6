"""The options of the `avatar-studio` commands, one frozen dataclass a command, apart from the code that runs them:
the command line is built from these (app/config_cli.py, each field's docstring its help), and `--help` must start
without torch, OpenCV or GL. The configs of training and synthetic captures live beside their code's package
(models/training/configs.py, models/capture/configs.py); the studio's in app/studio/config.py."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from models.avatars.names import PersonalTune
from models.ranges import Range
from render.camera import TURNTABLE_ELEVATION_DEG

PresetName = Literal["draft", "preview", "final"]
"""An avatar's quality presets (models/avatars/quality.py)."""


@dataclass(frozen=True)
class HeadPoseConfig:
    head: str = "builtin"
    """HEAD: builtin, demo (the demo avatar's person, an ICT-FaceKit identity), ict:PATH (the ICT npz or a
    FaceXModel/ folder) or flame:PATH (a FLAME .pkl)."""
    controls: Path | None = None
    """JSON file of controls: shape, expression (list or {name: weight}), pose, gaze, translation."""
    expression: tuple[str, ...] = ()
    """Expression weights NAME=W (or INDEX=W), applied after --controls."""


@dataclass(frozen=True)
class PreviewConfig(HeadPoseConfig):
    out: Path = Path("out/preview.png")
    """Output PNG (written atomically: an existing file is replaced only by a complete image)."""
    yaw_deg: float = 0.0
    """Camera orbit about the vertical axis, degrees; positive moves the camera to the subject's left."""
    pitch_deg: float = 0.0
    """Camera elevation, degrees."""
    size: tuple[Annotated[int, Range(8, 8192)], Annotated[int, Range(8, 8192)]] = (512, 512)
    """Image width and height in pixels."""
    pass_: Literal["shaded", "normals", "wireframe", "shadow"] = "shaded"
    """What to draw: lit mesh, normals as colours, mesh with edges, or the key light's shadow mask."""
    landmarks: bool = False
    """Draw the head model's landmarks."""
    shadows: bool = True
    """Cast shadows from the key light."""


@dataclass(frozen=True)
class MeshConfig(HeadPoseConfig):
    out: Path = Path("out/head.obj")
    """Output mesh, .obj or .ply."""


@dataclass(frozen=True)
class DatasetConfig:
    dataset: Path
    """Capture folder: ours (transforms_*.json with a head model), NerFACE's, or IMavatar's flame_params.json."""


HELD_OUT_FROM = 1000
"""Identity seeds from here up are the held-out people every evaluation of the prior uses: never in a corpus."""


@dataclass(frozen=True)
class CorpusConfig:
    out: Path = Path("out/corpus")
    """Folder to create: one capture a person (id0001, id0002, ...)."""
    identities: Annotated[int, Range(1, HELD_OUT_FROM - 1)] = 8
    """People in the corpus: identity seeds --first .. --first + N - 1 (shape, skin tone and features drawn from
    the seed: `synth --identity K`)."""
    first: Annotated[int, Range(1, HELD_OUT_FROM - 1)] = 1
    """The first person's identity seed."""
    head: str = "builtin"
    """HEAD: builtin, demo, ict:PATH or flame:PATH (ICT's 100 identity components give the widest spread of faces)."""
    scenes: str = "ambient"
    """Lighting scenes, a comma list; the K-th person is captured under the (K mod n)-th."""
    frames: Annotated[int, Range(10, 100000)] = 60
    """Frames of each person's range-of-motion script (held-out frames included)."""
    views: Annotated[int, Range(1, 16)] = 4
    """Cameras at once on every frame, evenly round the head (the seed's multi-view capture: the prior learns the
    whole head, back and top included, which a monocular scan never shows)."""
    size: Annotated[int, Range(16, 2048)] = 128
    """Width and height of every view's images, pixels."""


@dataclass(frozen=True)
class TrackConfig:
    video: Path
    """The video of one face (any format OpenCV decodes: mp4, mov, webm...)."""
    out: Path
    """Dataset folder to create (must not exist)."""
    head: str = "builtin"
    """HEAD: builtin, demo, ict:PATH or flame:PATH."""
    landmarker: Path | None = None
    """MediaPipe's face landmarker bundle (face_landmarker.task, from MediaPipe's model page), remembered once it
    works; default: $AVATAR_STUDIO_LANDMARKER, else the one remembered, else the one the set-up installs."""
    fps: Annotated[float, Range(0, 1000, above=True)] | None = None
    """Frames a second taken from the video (default: every frame; fewer frames track and train faster)."""
    seconds: Annotated[float, Range(0, 1e6, above=True)] | None = None
    """Use only the video's first SECONDS (default: all of it)."""
    size: Annotated[int, Range(32, 2048)] = 256
    """Width and height of the dataset's images, pixels."""
    crop: Literal["auto", "fixed", "follow"] = "auto"
    """fixed: one square crop about the face for the whole video (wider where the head travels); follow: each
    frame's crop follows the head (each its own principal point, the room one plate behind them all); auto: follow
    where one crop would leave the face at 80% of its size or less."""
    fov_deg: Annotated[float, Range(0, 170, above=True)] = 40.0
    """Horizontal field of view of the video's full frame, degrees (a guess unless you know your camera)."""
    test_fraction: Annotated[float, Range(0, 0.9, above=True)] = 0.1
    """The share of the frames held out as the test split (see --split)."""
    split: Literal["time", "view"] = "time"
    """time: the last part of the video is held out; view: the frames where the head is turned furthest from its
    usual facing are held out, so the avatar trains on the smaller turns and is measured beyond them."""
    iterations: Annotated[int, Range(1, 100000)] = 200
    """Fitting iterations (all frames at once; 400 took twice the fit's time for 0-3% less landmark error on four
    clips, docs/results.md "Tracking")."""
    shape_components: Annotated[int, Range(0)] = 20
    """Identity components fitted (0: the head model's mean shape)."""
    smooth: Annotated[float, Range(0, 1e6)] = 1.0
    """Scale of the frame-to-frame smoothness of pose and expression (0 for frames that are not a continuous
    motion, such as a set of photographs)."""
    blur: Annotated[float, Range(0, 1)] = 0.3
    """Frames whose face is sharper than this fraction of the video's median sharpness are kept."""
    overlay: bool = True
    """Write tracking/overlay.mp4: the fitted mesh over the frames."""
    room: Literal["auto", "plate", "frames"] = "auto"
    """What stands behind the person: plate, one background plate made of every frame's room (a camera that stood
    still); frames, each frame's own room (the frame with the person filled from around: a camera that moved, or
    water or traffic behind); auto: frames where the room moved (the report's room_residual_levels over 5)."""
    masks: Literal["auto", "selfie", "grabcut"] = "auto"
    """How the person's masks are cut: selfie, MediaPipe's selfie segmenter (the set-up installs its model);
    grabcut, OpenCV's GrabCut seeded by the face; auto: the segmenter where its model is installed."""


@dataclass(frozen=True)
class EvalConfig:
    avatar: Path
    """Avatar folder."""
    dataset: Path
    """Capture folder to evaluate on."""
    split: Literal["train", "val", "test"] = "test"
    """The capture's split to measure on (test: the held-out frames)."""
    out: Path = Path("out/eval")
    """Folder for metrics.json and side-by-side images."""
    max_frames: Annotated[int, Range(0)] = 0
    """Evaluate at most this many frames (0: all)."""
    every: Annotated[int, Range(1)] = 1
    """Evaluate every n-th frame of the split (a slow model on a long split)."""
    device: Literal["cpu", "cuda"] = "cpu"
    """Where the networks run."""


@dataclass(frozen=True)
class RenderCommandConfig:
    avatar: Path
    """Avatar folder."""
    out: Path = Path("out/render.png")
    """The PNG to write."""
    controls: Path | None = None
    """JSON controls (docs/formats.md); neutral when left out."""
    yaw_deg: float = 0.0
    """Camera orbit about the vertical axis, degrees; positive moves the camera to the subject's left."""
    pitch_deg: float = 0.0
    """Camera elevation, degrees."""
    buffer: Literal["rgb", "normals", "grad_normals", "depth", "opacity", "rgb_no_shadows", "rgb_light",
                    "shadow_change", "shading"] = "rgb"
    """Which buffer to write: rgb_no_shadows (without cast shadows), rgb_light (light reaching the surface),
    shadow_change (what the cast shadows take away) and shading (render - normals to the viewer) need an avatar
    with those effects."""
    preset: PresetName = "preview"
    """Render quality: the avatar's draft, preview or final setting (its presets.json, chosen by `bench`; else
    built-in: draft renders at half size with 6 samples a ray, preview 8, final 16). A preset may render fewer
    pixels; the image is scaled to --size."""
    size: Annotated[int, Range(8, 4096)] = 128
    """Width and height of the PNG, pixels."""
    device: Literal["cpu", "cuda"] = "cpu"
    """Where the networks run."""


@dataclass(frozen=True)
class PersonalizeConfig:
    scan: Path
    """A short capture of one new person (a synthetic capture, or a video through `track`): a neutral head turn and
    a few expressions."""
    prior: Path = Path("resources/prior")
    """The universal prior's folder (`prior-train`)."""
    out: Path = Path("out/personal")
    """The person's avatar folder to create."""
    minutes: Annotated[float, Range(0, 1e6)] = 3.0
    """Fine-tuning on the scan's frames (0: the avatar the neutral maps alone make, at once)."""
    steps: Annotated[int, Range(1)] | None = None
    """A step budget instead of (or as well as) --minutes."""
    lr: Annotated[float, Range(0, 1, above=True)] = 1e-3
    """Adam's learning rate (the seed's Section 4.2.5: 1e-3), decaying tenfold."""
    tune: PersonalTune = "all"
    """What fine-tuning changes: every weight, the decoder alone (the encoders kept as the prior has them), or the
    decoder's per-texel bias maps alone (what no frame saw stays the prior's: a whole head's outside)."""
    device: Literal["cpu", "cuda"] = "cpu"
    """Where the networks run."""
    seed: int = 0
    """Seed of the fine-tuning's ray sampling."""


@dataclass(frozen=True)
class AnimateConfig:
    avatar: Path
    """Avatar folder."""
    animation: Path
    """An animation file (JSON: app/animation.py; the studio's Export panel saves one)."""
    out: Path = Path("out/animation.mp4")
    """The mp4 to write (H.264); PNG frames go to a folder beside it unless --no-pngs."""
    size: Annotated[int, Range(8, 4096)] = 256
    """Width and height of the video's frames, pixels (even: H.264 needs it)."""
    preset: PresetName = "preview"
    """Render quality: the avatar's draft, preview or final setting (its presets.json, chosen by `bench`; else
    built-in: draft renders at half size with 6 samples a ray, preview 8, final 16). A preset may render fewer
    pixels; the image is scaled to --size."""
    pngs: bool = True
    """Also write the frames as PNGs into a folder beside the mp4."""
    meshes: Literal["none", "obj", "ply"] = "none"
    """Also write the posed guide mesh of every frame (FOLDER_meshes/frame_0000.obj ...), for other tools."""


@dataclass(frozen=True)
class ExportMeshConfig:
    avatar: Path
    """Avatar folder (primitives, prior or CoDyNeRF: their density makes the surface)."""
    out: Path = Path("out/avatar.ply")
    """The mesh to write: .ply (binary, vertex colours) or .obj (vertex colours as "v x y z r g b")."""
    resolution: Annotated[int, Range(8, 512)] = 96
    """Grid points along the head's longest side (the mesh's detail; time and size grow with its cube)."""
    controls: Path | None = None
    """A controls JSON to pose the avatar with (default: at rest)."""
    level: Annotated[float, Range(0, 1e9, above=True)] | None = None
    """The surface's density, per metre (default: where 1 cm of matter lets half the light through, 69.3; in a
    field that never gets that dense, half its highest density)."""


@dataclass(frozen=True)
class ExportConfig:
    avatar: Path
    """Avatar folder."""
    format: Literal["glb", "web"] = "glb"
    """glb: a glTF 2.0 binary (Blender, Unity with glTFast, three.js): the guide mesh with the expressions as morph
    targets, the jaw and eyes as a skeleton, a texture baked from the avatar, the animation; web: a folder to host,
    that .glb as avatar.glb with a player page (index.html: sliders, play and pause, an orbit camera) and three.js."""
    out: Path = Path("out/avatar.glb")
    """The file to write (glb), or the folder (web)."""
    animation: Path | None = None
    """An animation file (JSON, as `animate` reads) to include: expressions as morph weights, head, neck, jaw and
    gaze as joint rotations (camera channels are left out)."""
    texture_size: Annotated[int, Range(64, 8192)] = 1024
    """Width and height of the baked colour texture, pixels."""
    render_size: Annotated[int, Range(32, 4096)] = 256
    """Width and height of the renders the texture is baked from, pixels (time grows with its square; half the
    texture's size gives every texel of the face its own pixel)."""
    views: Annotated[int, Range(1, 64)] = 7
    """Cameras the texture is baked from across the yaws the avatar can show, at the head's height (and about as
    many again from above and below)."""
    preset: PresetName = "preview"
    """Render quality of the bake's renders: the samples and passes of the avatar's draft, preview or final setting
    (its image scale is left out: the renders are --render-size)."""


@dataclass(frozen=True)
class TurntableConfig:
    avatar: Path
    """Avatar folder."""
    out: Path = Path("out/turntable.mp4")
    """The mp4 to write (H.264); PNG frames go to a folder beside it unless --no-pngs."""
    frames: Annotated[int, Range(1, 100000)] = 120
    """Frames in the video: one turn (or one swing there and back) of the camera."""
    sweep_deg: Annotated[float, Range(0, 180)] | None = None
    """Swing the camera this many degrees to each side of the front; 0: a full turn (default: as far as the
    capture's views went and 10 degrees more, a full turn where they went round the head: a video's avatar has
    seen the head only from about the front)."""
    elevation_deg: Annotated[float, Range(-89, 89)] = TURNTABLE_ELEVATION_DEG
    """Camera height above the head's centre, degrees."""
    zoom: Annotated[float, Range(0.05, 20)] = 1.0
    """Camera distance: 1 frames the head; 2 is twice as close."""
    size: Annotated[int, Range(8, 4096)] = 256
    """Width and height of the video's frames, pixels (even: H.264 needs it)."""
    preset: PresetName = "preview"
    """Render quality: the avatar's draft, preview or final setting (its presets.json, chosen by `bench`; else
    built-in: draft renders at half size with 6 samples a ray, preview 8, final 16). A preset may render fewer
    pixels; the image is scaled to --size."""
    animate: bool = False
    """Talk while turning: the jaw and a smile follow slow waves."""
    fps: Annotated[float, Range(1, 240)] = 30.0
    """Frames a second of the video (120 frames at 30: a 4 s turn)."""
    pngs: bool = True
    """Also write the frames as PNGs into a folder beside the mp4."""


@dataclass(frozen=True)
class ReenactConfig:
    avatar: Path
    """Avatar folder to drive."""
    video: Path
    """The performance: a video of one face (any person), or a capture folder, or another avatar's folder (its
    capture's frames drive this one: "drive B from A's frames")."""
    out: Path = Path("out/reenact.mp4")
    """The mp4 to write (H.264); the animation goes beside it (OUT.json)."""
    landmarker: Path | None = None
    """MediaPipe's face landmarker bundle, as track's --landmarker (remembered; default: as track finds one)."""
    driver_head: str = ""
    """The head model the driver is tracked with (builtin, ict:PATH, flame:PATH); default: the avatar's own,
    which carries every expression."""
    size: Annotated[int, Range(16, 2048)] = 256
    """Width and height of the avatar's frames, pixels (even: H.264 needs it); a side-by-side video is twice as
    wide, the driver's frames on the left at the same size."""
    preset: PresetName = "preview"
    """Render quality: the avatar's draft, preview or final setting (its presets.json, chosen by `bench`; else
    built-in: draft renders at half size with 6 samples a ray, preview 8, final 16). A preset may render fewer
    pixels; the image is scaled to --size."""
    fps: Annotated[float, Range(0, 1000, above=True)] | None = None
    """Frames a second taken from the driving video (default: every frame); a capture's frames play at this rate
    (default 30)."""
    seconds: Annotated[float, Range(0, 1e6, above=True)] | None = None
    """Use only the driving video's first SECONDS."""
    neutral_frame: Annotated[int, Range(0)] | None = None
    """The driver's neutral frame (an index among the tracked frames); default: the calmest frame."""
    side_by_side: bool = True
    """The driver's frames beside the avatar (--no-side-by-side: the avatar alone)."""
    pngs: bool = False
    """Also write the frames as PNGs into a folder beside the mp4."""
    meshes: Literal["none", "obj", "ply"] = "none"
    """Also write the posed guide mesh of every frame (OUT_meshes/frame_0000.obj ...), for other tools."""
    iterations: Annotated[int, Range(1, 100000)] = 200
    """Fitting iterations of the tracker (as `track`'s)."""


@dataclass(frozen=True)
class BenchConfig:
    out: Path = Path("out/bench")
    """Folder for results.json, the charts, the capture and the avatars it trains."""
    quick: bool = False
    """Under 5 minutes on a 2-core CPU: a 64 px capture, 25 s of training per effect set, 3 test frames."""
    dataset: Path | None = None
    """A capture with a test split; by default a `sun` capture of the built-in head is synthesized into OUT."""
    avatars: tuple[Path, ...] = ()
    """Trained avatars of that capture whose rendering is measured (one per effect set); by default the ones
    the training curves train."""
    nerface: Path | None = None
    """A trained NerFACE avatar of the capture (timed and measured); by default an untrained one of the
    published size is timed (its weights do not change the work)."""
    train_seconds: Annotated[float, Range(0)] | None = None
    """Training seconds per effect set for the training curves (default 300; quick: 25; 0: no curves, measure
    the --avatars only)."""
    size: Annotated[int, Range(8, 4096)] | None = None
    """Image width and height, pixels (default 128; quick: 64)."""
    test_frames: Annotated[int, Range(1)] | None = None
    """Held-out test frames measured per setting (default 6; quick: 3)."""
    store_presets: bool = True
    """Write the chosen presets into each measured avatar (presets.json)."""



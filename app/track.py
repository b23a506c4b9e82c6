"""`avatar-studio track`: a monocular video of one face -> a capture dataset that `train` accepts.

The pipeline is models/tracking/pipeline.py (landmarks, the crop, the head model's fit, masks, the background plate,
the splits); this command reads its options, finds the landmarker bundle, calls it with progress bars, and reports
how well it went before anyone spends time training: landmark reprojection error per frame, frames dropped and why,
and an overlay video of the fitted mesh.

Everything is written to a folder of the program's own beside OUT (models/files.py: partial_folder) and renamed
to OUT only when complete.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from tqdm import tqdm

from app.capture_commands import next_train
from app.configs import TrackConfig
from app.errors import UserInputError
from app.progress import Progress, progress_callback
from app.user_config import config_folder, find_landmarker, remember, remembered
from models.files import partial_folder
from models.head.sources import load_head
from models.tracking import pipeline
from models.tracking.landmarker import packaged_bundle
from models.tracking.masks import MaskWayError, mask_way
from models.tracking.pipeline import Feedback, Tracked, write_capture
from models.tracking.video import video_info


def landmarker_path(cfg: TrackConfig) -> Path:
    """The face landmarker bundle: --landmarker, else as app/user_config.py finds one (find_landmarker), the
    packaged one last."""
    return find_landmarker(cfg.landmarker, packaged_bundle)


def remember_landmarker(cfg: TrackConfig, bundle: Path) -> None:
    """A --landmarker that worked is remembered, so that later runs need none (said in one line)."""
    if cfg.landmarker is None:
        return
    path = str(bundle.resolve())
    if remembered("landmarker") != path:
        try:
            where = remember("landmarker", path)
        except OSError as e:  # the run goes on: only the next one needs the flag again
            print(f"could not remember --landmarker in {config_folder()} ({e.strerror})", flush=True)
            return
        print(f"remembered --landmarker {path} in {where}: later runs need no --landmarker", flush=True)


def track_video(cfg: TrackConfig, model) -> Tracked:
    """The pipeline's first half (landmarks, the crop, the fit) with the bundle found, progress shown and a
    --landmarker that worked remembered (track's and reenact's)."""
    info = video_info(cfg.video)  # the video first: the input the user thinks of
    bundle = landmarker_path(cfg)
    tty = sys.stderr.isatty()
    bar = tqdm(desc="landmarks", unit="frame", disable=not tty)

    first: list[tuple[int, float]] = []  # the first frame's count and time: the rate from there on

    def landmarks(done: int, total: int | None) -> None:
        if tty:
            bar.total = total
            bar.n = done
            bar.refresh()
            return
        if not first:
            first.append((done, time.perf_counter()))
        if done % 25 == 0:  # a line every 25 frames in a log (the studio's job list shows its last line)
            print(f"landmarks: {done}" + (f" of about {total}" if total else "") + " frames"
                  + time_left(done, total, *first[0]), flush=True)

    fitting: list[Progress] = []

    def fitted(done: int, total: int) -> None:
        if not fitting:
            fitting.append(Progress("fitting", total, unit="iterations"))
        fitting[0].update(done)

    def found() -> None:
        bar.close()
        remember_landmarker(cfg, bundle)

    feedback = Feedback(say=lambda line: print(line, flush=True), landmarks=landmarks, fitting=fitted,
                        landmarks_found=found)
    try:
        return pipeline.track_video(cfg, model, bundle, info, feedback)
    finally:
        bar.close()


def time_left(done: int, total: int | None, done_at_start: int, start: float, now: float | None = None) -> str:
    """" (M:SS left)" at the rate since `start` (when `done_at_start` were done), or "" where there is none yet.

    >>> time_left(50, 200, 0, 100.0, now=110.0), time_left(1, 200, 1, 100.0, now=110.0), time_left(50, None, 0, 0.0)
    (' (00:30 left)', '', '')
    """
    now = time.perf_counter() if now is None else now
    if not total or done <= done_at_start or now <= start:
        return ""
    left = (total - done) * (now - start) / (done - done_at_start)
    return f" ({tqdm.format_interval(max(left, 0.0))} left)"


def run_track(cfg: TrackConfig) -> int:
    t_start = time.perf_counter()
    check_config(cfg)
    model = load_head(cfg.head)
    tr = track_video(cfg, model)
    with partial_folder(cfg.out) as partial:
        bar = Progress(f"cutting masks ({mask_way(cfg.masks)})", len(tr.kept), unit="frames")
        writing = progress_callback("writing the frames" + (" and the overlay" if cfg.overlay else ""), unit="images")
        report = write_capture(cfg, tr, model, partial, Feedback(masks=lambda done, _: bar.update(done),
                                                                 writing=writing))
        total = time.perf_counter() - t_start
        report["seconds"]["total"] = round(total, 2)
        report["seconds_per_frame"] = round(total / tr.read, 4)
        (partial / "tracking" / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    le = report["landmark_error_px"]
    print(f"wrote {cfg.out}: {report['splits']['train']} train, {report['splits']['val']} val, "
          f"{report['splits']['test']} test frames; landmark error median {le['median']:.2f} px, "
          f"95th percentile {le['p95']:.2f} px ({cfg.size} px images, the face {report['face_width_px']['median']:.0f} "
          f"px wide); {total:.1f} s ({report['seconds_per_frame']:.3f} s a frame)"
          + (f"; overlay {cfg.out / 'tracking' / 'overlay.mp4'}" if cfg.overlay else ""))
    small = small_face_note(report, tr.info.width)
    if small:
        print(small)
    plate = report["background_plate"]
    if plate.get("room") == "moving" or "rooms" in plate.get("behind_frames", ""):
        print(f"behind the person: {plate['behind_frames']} ({plate['why']}"
              + ("; a camera that moves, or water or traffic behind" if plate.get("room") == "moving" else "") + ")")
    print(next_train(cfg.out))
    return 0


def small_face_note(report: dict, width: int) -> str:
    """One line where the face is small in the video: how small, how it was found, and what it costs (the crop's
    pixels upsampled to the dataset's size); empty where it is not.

    >>> small_face_note({"source_face_px": 112.0, "faces_found_by": {"frame": 0, "following": 58, "search": 2},
    ...                  "upsampled": 1.0}, 1920)
    'the face is small in the video (112 px across, 6% of its 1920 px width): found in windows of the frame (60 frames)'
    >>> small_face_note({"source_face_px": 60.0, "faces_found_by": {"frame": 5}, "upsampled": 1.42}, 640)
    'the face is small in the video (60 px across, 9% of its 640 px width): the crop is upsampled 1.42x (less detail)'
    >>> small_face_note({"source_face_px": 280.0, "faces_found_by": {"frame": 50}, "upsampled": 1.0}, 512)
    ''
    """
    found = report["faces_found_by"]
    windows = sum(n for by, n in found.items() if by != "frame")
    parts = []
    if windows:
        parts.append(f"found in windows of the frame ({windows} frames)")
    if report["upsampled"] > 1.0:
        parts.append(f"the crop is upsampled {report['upsampled']:.2f}x (less detail)")
    if not parts:
        return ""
    face = report["source_face_px"]
    return (f"the face is small in the video ({face:.0f} px across, {face / width:.0%} of its {width} px width): "
            + "; ".join(parts))


def check_config(cfg: TrackConfig) -> None:
    if cfg.out.exists():
        raise UserInputError(f"{cfg.out}: already exists; choose a new dataset folder")
    if not 32 <= cfg.size <= 2048:
        raise UserInputError(f"--size {cfg.size}: must be 32..2048 pixels")
    if not 0 < cfg.fov_deg < 170:
        raise UserInputError(f"--fov-deg {cfg.fov_deg}: must be between 0 and 170 degrees")
    try:
        mask_way(cfg.masks)
    except MaskWayError as e:
        raise UserInputError(f"--{e}") from e

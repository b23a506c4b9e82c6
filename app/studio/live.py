"""Live driving's worker: a camera (an OpenCV device index) or a video file played in real time, each frame tracked
as it comes (MediaPipe's face landmarker in video mode, then models/tracking/live.py: the retargeting `reenact`
uses, smoothed), in a process of its own, so that neither the window's frames nor the neural render hold up the
tracker (nor it them) on Python's interpreter lock.

Latency over throughput: a reader thread keeps only the newest frame (a video file's frames come at their own
times; where the reader falls behind, the frames already late are skipped undecoded), the tracker takes the newest
one each time it is free, and the window keeps only the newest pose. Every pose carries the time its frame came
(time.perf_counter: one clock for every process on the machine), from which the window measures the time to the
avatar's pixels on screen."""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.animation import SLIDER_RANGES
from models.head.model import HeadModel

LIMITS = {key: SLIDER_RANGES[key] for key in ("expression", "jaw.open", "gaze")}
"""Carried values are kept inside the Controls panel's slider ranges (as reenact keeps them)."""


def is_camera(source: str) -> bool:
    """A source that is a whole number names a camera (OpenCV's device index); anything else a video file."""
    return source.strip().isdigit()


def open_capture(source: str):
    """The source opened with OpenCV (its start-up warnings kept off the terminal), and what is wrong with it ("" where
    nothing is): a camera that does not exist, a file that is not there or not a video OpenCV can read."""
    import cv2

    from models.tracking.landmarker import quiet_stderr

    if is_camera(source):
        with quiet_stderr():  # OpenCV's V4L2 back end warns on stderr for a camera that is not there
            cap = cv2.VideoCapture(int(source))
        if not cap.isOpened():
            return None, f"camera {source}: no camera there (OpenCV cannot open device {source}); give a video file " \
                "with --source VIDEO to drive the avatar from one"
        cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the newest frame, not a queue of old ones
        return cap, ""
    path = Path(source)
    if not path.is_file():
        return None, f"{source}: no such video file (a camera is given by its index: --source 0)"
    with quiet_stderr():
        cap = cv2.VideoCapture(str(path))
    if not cap.isOpened() or not cap.grab():
        cap.release()
        return None, f"{source}: not a video OpenCV can read"
    cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
    return cap, ""


def source_problem(source: str) -> str:
    """What is wrong with a live source, in one line ("" where it can be opened)."""
    cap, problem = open_capture(source)
    if cap is not None:
        cap.release()
    return problem


@dataclass
class Frame:
    index: int
    stamp: float
    """time.perf_counter when the frame came (a camera's read returned; a video file's frame was due)."""
    media_ms: int
    """The frame's time in the stream (increasing: the landmarker's video mode needs it)."""
    bgr: np.ndarray


class Feed:
    """A thread reading the source, keeping only its newest frame. A video file plays in real time: frame k is due
    k / fps seconds after the start, and frames already a frame late are skipped without being decoded."""

    def __init__(self, cap, camera: bool):
        import cv2

        self.cap, self.camera = cap, camera
        self.fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
        self.newest: Frame | None = None
        self.ended = False
        self.skipped = 0
        """Frames of a video file never decoded: they were late before the reader came to them."""
        self.cond = threading.Condition()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._read, name="live-feed", daemon=True)
        self.start = time.perf_counter()
        self.thread.start()

    def _read(self) -> None:
        k = 0
        try:
            while not self.stop.is_set():
                if self.camera:
                    ok, bgr = self.cap.read()
                    stamp = time.perf_counter()
                    media_ms = round(1e3 * (stamp - self.start))
                else:
                    while time.perf_counter() > self.start + (k + 1) / self.fps:  # late already: skip it
                        if not self.cap.grab():
                            break
                        k, self.skipped = k + 1, self.skipped + 1
                    ok, bgr = self.cap.read()
                    wait = self.start + k / self.fps - time.perf_counter()
                    if ok and wait > 0:
                        time.sleep(wait)
                    stamp = time.perf_counter()
                    media_ms = round(1e3 * k / self.fps)
                if not ok:
                    break
                with self.cond:
                    self.newest = Frame(k, stamp, media_ms, bgr)
                    self.cond.notify_all()
                k += 1
        finally:
            with self.cond:
                self.ended = True
                self.cond.notify_all()

    def next_after(self, index: int, timeout_s: float = 0.1) -> Frame | None:
        """The newest frame if it is newer than `index` (waiting up to timeout_s for one); None: none yet."""
        with self.cond:
            self.cond.wait_for(lambda: self.ended or (self.newest is not None and self.newest.index > index),
                               timeout_s)
            f = self.newest
            return f if f is not None and f.index > index else None

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=2)
        self.cap.release()


@dataclass
class Pose:
    """The avatar's channels for one tracked frame."""

    index: int
    stamp: float
    """When its frame came (time.perf_counter)."""
    channels: dict[str, float]
    track_ms: float
    """The landmarker's and the retargeting's time for it."""
    dropped: int
    """Frames that came and were never tracked, so far (a newer one was there when the tracker was free)."""


UNASKED_S = 0.25
"""Where the window has not asked for a pose for this long (its frames are slow, a request was lost), the tracker
tracks one anyway."""


def track_from(asked_for: float | None, last_pose: float, track_s: float, now: float) -> float:
    """When to track the next frame (time.perf_counter): so that its pose is ready when the window asked for it
    (`asked_for`: when the renderer should be free), tracking taking `track_s`; unasked, UNASKED_S after the last
    pose. Tracking sooner would only make a pose that waits, older, on the sliders, and take the cores the render
    needs.

    >>> track_from(10.100, 9.9, 0.012, 10.0)  # the renderer free at 10.100: track at 10.088
    10.088
    >>> track_from(None, 9.9, 0.012, 10.0)  # not asked: 0.25 s after the last pose
    10.15
    """
    return round(asked_for - track_s if asked_for is not None else last_pose + UNASKED_S, 9)


def serve(source: str, bundle: str, head: HeadModel, results, commands) -> None:
    """The live process: open the source, then track its newest frame when the window will want a pose (track_from),
    sending each pose; ("want", T) asks for one at T (time.perf_counter), ("neutral",) makes the next face the
    neutral one, ("quit",) ends it."""
    import cv2

    from models.tracking.landmarker import Landmarker
    from models.tracking.live import LiveRetarget

    cap, problem = open_capture(source)
    if cap is None:
        results.put(("error", problem))
        return
    try:
        landmarker = Landmarker(bundle, max_faces=1, video=True)
    except ValueError as e:  # BundleError: the bundle named is not a landmarker
        results.put(("error", str(e)))
        cap.release()
        return
    retarget = LiveRetarget(head, LIMITS)
    feed = Feed(cap, is_camera(source))
    results.put(("started", feed.fps, is_camera(source)))
    last, tracked, no_face = -1, 0, 0
    asked_for: float | None = time.perf_counter()  # the first pose at once
    last_pose, track_times = time.perf_counter(), [0.010]
    try:
        while True:
            # The pose a little before it is due (8 ms): one that comes just after the window's frame began waits
            # for the whole frame.
            track_s = float(np.median(track_times[-9:])) + 0.008
            wait = track_from(asked_for, last_pose, track_s, time.perf_counter()) - time.perf_counter()
            if commands.poll(max(wait, 0.0)):
                msg = commands.recv()
                if msg[0] == "quit":
                    return
                if msg[0] == "neutral":
                    retarget.set_neutral()
                if msg[0] == "want":
                    asked_for = msg[1]
                continue
            frame = feed.next_after(last)
            if frame is None:
                if feed.ended:
                    results.put(("ended", "the video ended" if not feed.camera else "the camera stopped"))
                    return
                continue
            last = frame.index
            t0 = time.perf_counter()
            faces = landmarker.detect(cv2.cvtColor(frame.bgr, cv2.COLOR_BGR2RGB), frame.media_ms)
            if not faces:
                no_face += 1
                results.put(("no_face", frame.index))
                continue
            channels = retarget(faces[0], frame.stamp)
            asked_for, last_pose = None, time.perf_counter()
            track_times.append(last_pose - t0)
            tracked += 1
            dropped = frame.index + 1 - tracked - no_face
            results.put(("pose", Pose(frame.index, frame.stamp, channels, 1e3 * (time.perf_counter() - t0),
                                      dropped)))
    except (EOFError, OSError, KeyboardInterrupt):  # the window is gone
        return
    finally:
        feed.close()
        landmarker.close()
        with contextlib.suppress(OSError, ValueError):
            results.put(("closed",))


@dataclass
class LiveFigures:
    """Live driving measured: each shown live render's time from its camera frame to its pixels on screen, when each
    was shown, the tracker's time per frame, and which source frame is on screen."""

    latency_ms: list[float] = field(default_factory=list)
    age_ms: list[float] = field(default_factory=list)
    """Each live request's pose's age when it went to the renderer (from its camera frame)."""
    render_ms: list[float] = field(default_factory=list)
    """Each shown live request's render time."""
    delivery_ms: list[float] = field(default_factory=list)
    """Each shown live render's time from its pixels' arrival in the window's process to their presentation."""
    passes: dict[str, int] = field(default_factory=dict)
    """How many shown live renders each pass made (neural.py's live_pass chooses it)."""
    shown_at: list[float] = field(default_factory=list)
    track_ms: list[float] = field(default_factory=list)
    dropped: int = 0
    poses: int = 0
    pending: dict[int, tuple[int, float]] = field(default_factory=dict)
    """Render request id -> its source frame and that frame's time (time.perf_counter), until its first pixels are
    drawn."""
    drawn: list[tuple[int, float, float]] = field(default_factory=list)
    """Source frames (and times) whose renders the frame being drawn shows first, until it is presented."""
    on_screen: int = -1
    """The source frame whose render is on screen (-1: none yet)."""

    def took(self, pose) -> None:
        self.poses += 1
        self.track_ms.append(pose.track_ms)
        self.dropped = pose.dropped

    def submitted(self, request_id: int, index: int, stamp: float | None) -> None:
        """A render request went out for the pose of source frame `index` (stamp None: not a live pose)."""
        if stamp is not None:
            self.pending = {rid: v for rid, v in self.pending.items() if rid > request_id - 4}
            self.pending[request_id] = (index, stamp)
            self.age_ms.append(1e3 * (time.perf_counter() - stamp))

    def render_s(self) -> float:
        """The median of the last 5 live renders' times, seconds (0 before the first): when the renderer should be
        free again after a request. (Timing the next pose by the interval between requests instead, which includes
        the wait for that pose, slowed the renders shown from 10.8 to 5.5 a second on the demo: a late pose makes
        the next one later.)

        >>> LiveFigures(render_ms=[70.0, 90.0, 64.0, 200.0, 66.0, 68.0]).render_s()  # the median of the last five
        0.068
        """
        return float(np.median(self.render_ms[-5:])) / 1e3 if self.render_ms else 0.0

    def drawing(self, request_id: int, render_ms: float, pass_name: str = "", arrived: float | None = None) -> None:
        """The frame being drawn shows a pass of this request, rendered in render_ms, its pixels in the window's
        process since `arrived` (time.perf_counter)."""
        if request_id in self.pending:
            index, stamp = self.pending.pop(request_id)
            self.drawn.append((index, stamp, stamp if arrived is None else arrived))
            self.render_ms.append(render_ms)
            self.passes[pass_name] = self.passes.get(pass_name, 0) + 1

    def shown(self, now: float) -> None:
        """The frame drawn is presented: its live renders are on screen."""
        for index, stamp, arrived in self.drawn:
            self.latency_ms.append(1e3 * (now - stamp))
            self.delivery_ms.append(1e3 * (now - arrived))
            self.shown_at.append(now)
            self.on_screen = max(self.on_screen, index)
        self.drawn = []

    def report(self, live) -> dict:
        """The figures as the scripted run's report keeps them (benchmarks/bench_live.py)."""
        t = self.shown_at
        return {"poses": self.poses, "shown": len(self.latency_ms), "dropped": self.dropped,
                "fps_shown": round((len(t) - 1) / (t[-1] - t[0]), 2) if len(t) > 1 and t[-1] > t[0] else 0.0,
                "latency_ms": [round(v, 1) for v in self.latency_ms],
                "shown_at_s": [round(v - t[0], 4) for v in t],
                "track_ms_median": round(float(np.median(self.track_ms)), 2) if self.track_ms else None,
                "age_at_request_ms_median": round(float(np.median(self.age_ms)), 1) if self.age_ms else None,
                "render_ms_median": round(float(np.median(self.render_ms)), 1) if self.render_ms else None,
                "delivery_ms_median": round(float(np.median(self.delivery_ms)), 1) if self.delivery_ms else None,
                "passes": dict(self.passes),
                "on_screen": self.on_screen, "state": None if live is None else live.state}


class LiveWorker:
    """The window's side of the live process: its newest pose (`pose`, numbered by `received`), its state and
    message; `wake()` is called as each pose comes (the window wakes for it where the renderer is free: where it is
    not, the window's next frame takes the pose, and frames drawn for poses no one could render would only take
    the cores the render needs)."""

    def __init__(self, source: str, bundle: Path, head: HeadModel, wake: Callable[[], None]):
        ctx = mp.get_context("spawn")
        self.source = source
        self.wake = wake
        self._results = ctx.Queue()
        inbox, self._commands = ctx.Pipe(duplex=False)
        self.pose: Pose | None = None
        self.received = 0
        self.no_face = 0
        self.state = "starting"
        """starting, running, ended (the video ended, the camera stopped), failed (the message says why), stopped."""
        self.message = ""
        self.fps = 0.0
        """The source's frame rate."""
        self._proc = ctx.Process(target=serve, args=(source, str(bundle), head, self._results, inbox),
                                 name="live-tracking", daemon=True)
        # Started from a thread: starting sends the new interpreter its arguments, the head model among them (ICT's
        # full model is 33 MB pickled), which the window's thread must not wait for.
        self._starter = threading.Thread(target=self._proc.start, name="live-start", daemon=True)
        self._starter.start()
        self._reader = threading.Thread(target=self._read, name="live-results", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            try:
                msg = self._results.get()
            except (EOFError, OSError, ValueError):
                return
            kind = msg[0]
            if kind == "pose":
                self.pose = msg[1]
                self.received += 1
                self.wake()
            elif kind == "no_face":
                self.no_face += 1
            elif kind == "started":
                self.state, self.fps = "running", msg[1]
            elif kind in ("ended", "error"):
                self.state, self.message = ("ended" if kind == "ended" else "failed"), msg[1]
                self.wake()
            elif kind == "closed":
                return

    def check(self) -> None:
        """A process that died without a word (a crash in the landmarker) fails live driving with its exit code."""
        if self.state in ("starting", "running") and self._proc.exitcode is not None and self._reader.is_alive():
            time.sleep(0.05)  # its last messages may still be on their way
            if self.state in ("starting", "running"):
                self.state, self.message = "failed", f"live: the tracker stopped (exit code {self._proc.exitcode})"

    def set_neutral(self) -> None:
        self._send(("neutral",))

    def want(self, at: float) -> None:
        """Ask for a pose at `at` (time.perf_counter: when the renderer should be free for it)."""
        self._send(("want", at))

    def _send(self, msg: tuple) -> None:
        with contextlib.suppress(OSError, ValueError, BrokenPipeError):
            self._commands.send(msg)

    def close(self, wait: bool = True) -> None:
        """End the live process (its source released); without `wait`, a thread waits for it (a camera's read may
        hold it a moment), not the window."""
        self._send(("quit",))
        if self.state in ("starting", "running"):
            self.state = "stopped"
        if wait:
            self._end()
        else:
            threading.Thread(target=self._end, name="live-close", daemon=True).start()

    def _end(self) -> None:
        self._starter.join()
        self._proc.join(timeout=5)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(timeout=5)

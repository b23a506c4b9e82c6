"""Frame sequences to an H.264 mp4 (ffmpeg from imageio-ffmpeg: OpenCV's wheel has no H.264 encoder) and
to numbered PNGs. The mp4 is written beside its final name and renamed when complete, so a cancelled or
failed export never leaves a file that looks finished."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from PIL import Image


def write_video(frames: Iterable[np.ndarray], mp4: str | Path, fps: float = 30.0, png_dir: str | Path | None = None
                ) -> int:
    """Write (H,W,3) uint8 frames to `mp4` (H.264, yuv420p, even sizes) and, with png_dir, as
    png_dir/frame_0000.png ...; returns the number of frames. An exception from the frames (a cancel) leaves
    no mp4 behind."""
    mp4 = Path(mp4)
    mp4.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=mp4.parent, prefix=f".{mp4.stem}.partial-", suffix=mp4.suffix)  # our own name
    os.fchmod(fd, 0o644)  # an ordinary file once renamed (mkstemp's is owner-only)
    os.close(fd)
    tmp = Path(name)
    if png_dir is not None:
        Path(png_dir).mkdir(parents=True, exist_ok=True)
    writer = None
    n = 0
    try:
        for frame in frames:
            frame = np.ascontiguousarray(frame[..., :3], np.uint8)
            h, w = frame.shape[:2]
            if writer is None:
                if h % 2 or w % 2:
                    raise ValueError(f"{mp4}: H.264 (yuv420p) needs even frame sizes, got {w}x{h}")
                import imageio_ffmpeg  # where a video is written: `train` imports this module and writes none

                writer = imageio_ffmpeg.write_frames(str(tmp), (w, h), fps=fps, codec="libx264",
                                                     pix_fmt_out="yuv420p", quality=None,
                                                     output_params=["-crf", "18"], macro_block_size=1)
                writer.send(None)
            writer.send(frame)
            if png_dir is not None:
                Image.fromarray(frame).save(Path(png_dir) / f"frame_{n:04d}.png")
            n += 1
        if writer is None:
            raise ValueError(f"{mp4}: no frames to write")
        writer.close()
        writer = None
        os.replace(tmp, mp4)
    finally:
        if writer is not None:
            writer.close()
        tmp.unlink(missing_ok=True)
    return n

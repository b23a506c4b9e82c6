"""The primitives' hot loops in C (native_march.c), for the CPU: built with the system's C compiler into the
user's cache at set-up (`make native`, which finds the compiler and reports it; or at first use where the set-up
did not run), called through ctypes (which lets go of Python's lock for the call, so two threads run at once).

- `march`, display's march: the torch march (march.py) runs each wave as tens of small tensor operations,
  gathering and scattering every sample's values between them; on the demo avatar at 256 px its colour frame
  took 92-112 ms of marching after its decode on two cores, where the studio asks for full-quality pixels 150 ms
  after a slider moves, their way to the window included. One ray at a time, the C loop keeps a ray's light, sums
  and lookups in registers and stops at the candidate where the ray turns opaque: 44 ms (bench_primitives).
- `trilinear`, training's lookups with their gradients (the torch march takes it for float32 grids on the CPU): the
  3D grid_sample's backward was a sixth of a training step's time.

The torch march stays the reference (tests hold the two together) and the path for CUDA; dispatch.py chooses which
runs (`unavailable` says why not C). `AVATAR_STUDIO_NATIVE=0` turns both off (torch then does all, as on a machine
without a C compiler)."""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import torch

from models.avatars.base import RenderCancelled
from models.avatars.primitives import march as m

SOURCE = Path(__file__).with_name("native_march.c")
MAX_CHANNELS = 64
"""native_march.c's colour channels at most (its per-ray sums live on the stack)."""
CHUNK_RAYS = 2048
"""Rays a call: should_stop is asked between calls (a few milliseconds of marching each)."""

FLAGS = ("-O3", "-fno-math-errno", "-fPIC", "-shared", "-std=c11")
"""The compiler's flags (with the source, what names the built library). -std=c11 keeps floating point as written
(no fused multiply-adds: -ffp-contract=off), so every build marches the same numbers; -fno-math-errno lets sqrtf be
one instruction (nothing reads errno)."""
NATIVE_FLAGS = ("-march=native",)
"""Tried first: the instructions of the processor it is built on (AVX2 on today's x86 machines): display's march of
the child's 30-minute whole head, 256 px, two threads, 78-83 ms against 90-102 (`-O3` alone) on an AMD EPYC, the
same pixels. Where the compiler refuses them, FLAGS alone. The library is then named by the processor too
(`processor_key`), so a cache shared by two machines holds one for each."""

_lock = threading.Lock()
_library: ctypes.CDLL | None = None
_failure: str | None = None


def cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "avatar-studio" / "native"


def compiler() -> str | None:
    return os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")


def processor_key() -> str:
    """What the processor can do, as NATIVE_FLAGS builds for it: Linux's CPU flags (/proc/cpuinfo), else the
    platform's name for it."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.split(":")[0].strip() in ("flags", "Features"):
                return f"{platform.machine()} {line.split(':', 1)[1].strip()}"
    except OSError:
        pass
    return f"{platform.machine()} {platform.processor()}"


def build(source: Path = SOURCE, out_dir: Path | None = None) -> Path:
    """The shared library of `source`, compiled once per source text, flags and (with NATIVE_FLAGS) processor (their
    hash names the file), atomically (a temporary file renamed into place: another process building it at once is
    harmless): with NATIVE_FLAGS where the compiler takes them, else without. Raises RuntimeError naming the problem
    where it cannot be built."""
    out_dir = out_dir or cache_dir()
    ways = []
    for extra in (NATIVE_FLAGS, ()):
        flags = (*FLAGS, *extra)
        named_by = source.read_bytes() + " ".join(flags).encode() + (processor_key().encode() if extra else b"")
        ways.append((flags, out_dir / f"{source.stem}-{hashlib.sha256(named_by).hexdigest()[:16]}.so"))
    for _, lib in ways:
        if lib.is_file():
            return lib
    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler found (cc, gcc or clang; install build-essential)")
    out_dir.mkdir(parents=True, exist_ok=True)
    error = ""
    for flags, lib in ways:
        fd, tmp = tempfile.mkstemp(dir=out_dir, suffix=".so")
        os.close(fd)
        try:
            done = subprocess.run([cc, *flags, "-o", tmp, str(source), "-lm"],
                                  capture_output=True, text=True, timeout=120)
            if done.returncode == 0:
                os.replace(tmp, lib)
                return lib
            error = f"{cc} failed on {source}: {done.stderr.strip()[-2000:]}"
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    raise RuntimeError(error)


def library() -> ctypes.CDLL | None:
    """The built march, or None (turned off, or it could not be built: `failure()` says why)."""
    global _library, _failure
    if os.environ.get("AVATAR_STUDIO_NATIVE", "1") == "0":
        return None
    with _lock:
        if _library is None and _failure is None:
            try:
                lib = ctypes.CDLL(str(build()))
                p, i64, i32, f32 = ctypes.c_void_p, ctypes.c_int64, ctypes.c_int, ctypes.c_float
                lib.march_rays.argtypes = [i64, p, p, p, p, i32, i64, i32, i32, p, p, p, p, p, p, i32, f32, f32,
                                           p, p, p, p]
                lib.march_rays.restype = None
                lib.lookup_forward.argtypes = [i64, p, p, p, i32, i32, p]
                lib.lookup_forward.restype = None
                lib.lookup_backward.argtypes = [i64, p, p, p, i32, i32, p, p, p]
                lib.lookup_backward.restype = None
                _library = lib
            except (OSError, RuntimeError, subprocess.SubprocessError) as e:
                _failure = str(e)
        return _library


def failure() -> str | None:
    return _failure


def unavailable(prims: m.Primitives, origins: torch.Tensor, display: bool) -> str:
    """Why the C code cannot do this march ("" where it can): display's march (`march`) wants CPU tensors, no
    gradient and at most MAX_CHANNELS colour channels; training's lookups (`trilinear`) float32 grids on the CPU;
    both the library built."""
    device = prims.density.device if prims.density.device.type != "cpu" else origins.device
    if device.type != "cpu":
        return f"tensors on {device.type}"
    if display and torch.is_grad_enabled():
        return "gradients wanted"
    if display and prims.colour.shape[-1] > MAX_CHANNELS:
        return f"{prims.colour.shape[-1]} colour channels (C holds {MAX_CHANNELS})"
    if not display and prims.density.dtype != torch.float32:
        return f"{str(prims.density.dtype).removeprefix('torch.')} grids"
    if library() is None:
        return failure() or "AVATAR_STUDIO_NATIVE=0"
    return ""


def _ptr(t: torch.Tensor) -> ctypes.c_void_p:
    return ctypes.c_void_p(t.data_ptr())


def march(origins: torch.Tensor, directions: torch.Tensor, background: torch.Tensor, prims: m.Primitives,
          lists: m.CandidateLists, samples: int, stop_below: float, min_weight: float, parts: int = 1,
          should_stop: Callable[[], bool] | None = None) -> m.MarchOutput:
    """The display march (march.march with adaptive samples, early termination and colour looked up only where it
    shows) of R rays in C, on `parts` threads (the screen dealt in stripes as march_in_parts deals it);
    should_stop is asked between calls of CHUNK_RAYS rays and yes raises RenderCancelled."""
    lib = library()
    assert lib is not None, failure()
    R, C = len(origins), prims.colour.shape[-1]
    f32 = lambda t: t.detach().to(torch.float32).contiguous()
    o, d = f32(origins), f32(directions)
    bg = f32(background if background.dim() == 2 else background.reshape(3))
    frames = m.box_frames(origins, prims)
    to_box, centres = f32(frames.to_box), f32(prims.centres)
    values = f32(torch.cat([prims.density[..., None], prims.colour], -1))  # (P,M,M,M,1+C)
    P, M = values.shape[:2]
    i64 = lambda t: t.detach().to(torch.int64).contiguous()
    list_prims, start, count = i64(lists.prims), i64(lists.start), i64(lists.count)
    out = torch.empty(R, C, dtype=torch.float32)
    opacity, depth = torch.empty(R, dtype=torch.float32), torch.empty(R, dtype=torch.float32)
    if R == 0:
        return m.MarchOutput(out[:, :3], out[:, 3:], opacity, depth, 0, 0)
    if parts > 1 and R >= 2 * parts:
        groups = [i64(g) for g in m.stripe_groups(directions, parts)]
    else:
        groups = [torch.arange(R, dtype=torch.int64)]
    # The groups' calls, taken in turn by `parts` threads as each becomes free: a thread that the window (or
    # anything else) holds up takes fewer of them, where with a group a thread the frame waited for the slower.
    chunks = [g[a:a + CHUNK_RAYS] for a in range(0, max(len(g) for g in groups), CHUNK_RAYS) for g in groups
              if a < len(g)]
    stats = [torch.zeros(2, dtype=torch.int64) for _ in chunks]

    def one(k: int) -> None:
        if should_stop is not None and should_stop():
            raise RenderCancelled
        chunk = chunks[k]
        lib.march_rays(len(chunk), _ptr(chunk), _ptr(o), _ptr(d), _ptr(bg), int(bg.dim() == 2), P, M, C,
                       _ptr(centres), _ptr(to_box), _ptr(values), _ptr(list_prims), _ptr(start), _ptr(count),
                       int(samples), float(stop_below), float(min_weight), _ptr(out), _ptr(opacity), _ptr(depth),
                       _ptr(stats[k]))

    if len(groups) == 1:
        for k in range(len(chunks)):
            one(k)
    else:
        with ThreadPoolExecutor(len(groups)) as pool:
            futures = [pool.submit(one, k) for k in range(len(chunks))]
            try:
                for f in futures:
                    f.result()
            finally:
                for f in futures:
                    f.cancel()
    dtype = prims.density.dtype
    lookups, segments = (int(sum(s[i] for s in stats)) for i in (0, 1))
    return m.MarchOutput(out[:, :3].to(dtype), out[:, 3:].to(dtype), opacity.to(dtype), depth.to(dtype), lookups,
                         segments)


class TrilinearLookup(torch.autograd.Function):
    """values (P,M,M,M,C) of primitives prim (N,) at box coordinates local (N,3) in [-1, 1], trilinearly (march's
    `trilinear` and `lookup` read the same), with gradients for the values and the coordinates: in C (training's
    lookups; the 3D grid_sample's backward took a sixth of a training step's CPU time on the d3 capture, its
    forward and backward a quarter)."""

    @staticmethod
    def forward(ctx, values: torch.Tensor, prim: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        lib = library()
        assert lib is not None, failure()
        v = values.detach().to(torch.float32).contiguous()
        p = prim.to(torch.int64).contiguous()
        x = local.detach().to(torch.float32).contiguous()
        M, C = v.shape[1], v.shape[-1]
        out = torch.empty(len(p), C, dtype=torch.float32)
        lib.lookup_forward(len(p), _ptr(p), _ptr(x), _ptr(v), M, C, _ptr(out))
        ctx.save_for_backward(v, p, x)
        ctx.dtypes = (values.dtype, local.dtype)
        return out.to(values.dtype)

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        lib = library()
        v, p, x = ctx.saved_tensors
        M, C = v.shape[1], v.shape[-1]
        g = grad_out.detach().to(torch.float32).contiguous()
        grad_values = torch.zeros_like(v)
        grad_local = torch.empty_like(x)
        lib.lookup_backward(len(p), _ptr(p), _ptr(x), _ptr(v), M, C, _ptr(g), _ptr(grad_values), _ptr(grad_local))
        return grad_values.to(ctx.dtypes[0]), None, grad_local.to(ctx.dtypes[1])


def trilinear(values: torch.Tensor, prim: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
    """(N,C): TrilinearLookup (in C, with gradients)."""
    return TrilinearLookup.apply(values, prim, local)


def main() -> int:
    """Build the library now, at set-up (`make native`), and say where, or why not: without it the torch march runs
    (dispatch.py says so each time), so a machine without a C compiler still renders. Exit status 0 either way."""
    try:
        lib = build()
    except (OSError, RuntimeError, subprocess.SubprocessError) as e:
        print(f"the primitives' C march is not built ({e}); the torch march runs instead", file=sys.stderr)
        return 0
    print(f"the primitives' C march: {lib} (compiler {compiler()})")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Progress lines: redrawn on a terminal, a line every tenth of the way in a log."""

from __future__ import annotations

import io
import re

from app.progress import Progress


def test_a_log_gets_a_line_every_tenth():
    out = io.StringIO()
    p = Progress("turntable", 24, stream=out, tty=False)
    for k in range(1, 25):
        p.update(k)
    lines = out.getvalue().splitlines()
    # 24 frames: the tenths fall at 2.4, 4.8, ... frames, so the lines come at frames 3, 5, 8, 10, 12, 15, 17, 20,
    # 22 and 24 (the last one always).
    assert [int(line.split()[1].split("/")[0]) for line in lines] == [3, 5, 8, 10, 12, 15, 17, 20, 22, 24]
    assert lines[-1].startswith("turntable: 24/24 frames (") and lines[-1].endswith(" in all)")


def test_a_log_line_says_the_time_left_and_the_last_the_time_taken(monkeypatch):
    """A clock at 2 s a frame from the first update (frame 0) on: after frame k, (10 - k) frames are 2(10 - k) s
    away; the last line says the 20 s the ten took."""
    now = [100.0]
    monkeypatch.setattr("tqdm.std.time", lambda: now[0])
    out = io.StringIO()
    p = Progress("fitting", 10, unit="iterations", stream=out, tty=False)
    for k in range(0, 11):
        now[0] = 100.0 + 2 * k
        p.update(k)
    lines = out.getvalue().splitlines()
    assert lines[0] == "fitting: 1/10 iterations (00:18 left)" and lines[4] == "fitting: 5/10 iterations (00:10 left)"
    assert lines[-1] == "fitting: 10/10 iterations (00:20 in all)" and len(lines) == 10


def test_a_terminal_gets_one_line_redrawn():
    out = io.StringIO()
    p = Progress("synth", 3, stream=out, tty=True)
    for k in (1, 2, 3):
        p.update(k, "ok")
    assert out.getvalue().count("\r") == 3 and out.getvalue().endswith("synth: 3/3 frames  ok   \n")


def test_a_terminal_bar_says_the_time_left_then_the_time_taken():
    out = io.StringIO()
    p = Progress("turntable", 4, stream=out, tty=True)
    for k in range(1, 5):
        p.update(k)
    first, second, _, last = out.getvalue().split("\r")[1:]
    # 1 of 4 is 25%: 3 of the bar's 12 cells; no rate yet after the first frame, so no time left either
    assert first == " 25%|###         | ? left  turntable: 1/4 frames   "
    assert re.fullmatch(r" 50%\|###### {6}\| \d\d:\d\d left  turntable: 2/4 frames {3}", second)
    assert re.fullmatch(r"100%\|#{12}\| \d\d:\d\d in all  turntable: 4/4 frames {3}\n", last)


def test_stages_each_get_a_bar_and_a_stage_begun_again_a_new_one(capsys):
    """A whole head reads and places its frames twice (the inside's, then the outside's): each time each stage
    writes its lines, ending at its total (a bar reused once finished wrote nothing the second time)."""
    from app.progress import progress_by_stage

    update = progress_by_stage()
    for _ in range(2):
        for stage in ("reading the frames", "placing the mesh in the frames"):
            for k in range(1, 5):
                update(stage, k, 4)
    ends = [line.split(" (")[0] for line in capsys.readouterr().err.splitlines() if "4/4" in line]
    assert ends == ["reading the frames: 4/4 frames", "placing the mesh in the frames: 4/4 frames"] * 2

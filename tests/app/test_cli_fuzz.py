"""Every subcommand on bad inputs, from a table: missing, empty, truncated, wrong type, out of range, unwritable
output, existing output. Each must end with exit status 2 and one line naming the input, and leave every file
that was there before as it was."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest

from app.cli import main

DEMO = Path(__file__).resolve().parents[2] / "resources" / "demo_avatar"


@pytest.fixture(scope="module")
def place(tmp_path_factory) -> Path:
    """A folder of things a user might point the commands at."""
    root = tmp_path_factory.mktemp("fuzz")
    shutil.copytree(DEMO, root / "avatar")
    (root / "empty_dir").mkdir()
    (root / "empty.json").write_text("")
    (root / "list.json").write_text("[1, 2]")
    (root / "truncated.json").write_text('{"expression": [0.1, ')
    (root / "afile").write_text("not a folder")
    (root / "video.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"\x00" * 40)  # a header and nothing else
    (root / "text.mp4").write_text("hello")
    (root / "existing.png").write_bytes(b"\x89PNG\r\n\x1a\n user's picture")
    (root / "existing_dataset").mkdir()
    (root / "existing_dataset" / "notes.txt").write_text("mine")
    broken = root / "broken_avatar"
    shutil.copytree(DEMO, broken)
    (broken / "avatar.json").write_text((broken / "avatar.json").read_text()[:200])
    capture = root / "capture"
    capture.mkdir()
    for split in ("train", "val", "test"):
        (capture / f"transforms_{split}.json").write_text(json.dumps({
            "camera_angle_x": 0.5, "intrinsics": [40.0, 40.0, 16.0, 16.0], "width": 32, "height": 32,
            "head_model": "builtin", "frames": [{"file_path": "images/0.png", "transform_matrix": [
                [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.6], [0, 0, 0, 1]], "controls": {}}]}))
    (capture / "images").mkdir()
    (capture / "images" / "0.png").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")  # truncated
    return root


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


# (name, argv with {p} for the folder above, a word the one line must contain)
CASES = [
    # preview / mesh: controls files, outputs
    ("preview: controls missing", ["preview", "--controls", "{p}/nope.json", "--out", "{p}/o.png"], "nope.json"),
    ("preview: controls empty", ["preview", "--controls", "{p}/empty.json", "--out", "{p}/o.png"], "empty.json"),
    ("preview: controls a list", ["preview", "--controls", "{p}/list.json", "--out", "{p}/o.png"], "list.json"),
    ("preview: controls truncated", ["preview", "--controls", "{p}/truncated.json", "--out", "{p}/o.png"],
     "truncated.json"),
    ("preview: size 0", ["preview", "--size", "0", "0", "--out", "{p}/o.png"], "--size"),
    ("preview: yaw inf", ["preview", "--yaw-deg", "inf", "--out", "{p}/o.png"], "--yaw-deg"),
    ("preview: output under a file", ["preview", "--out", "{p}/afile/o.png"], "afile"),
    ("preview: head missing", ["preview", "--head", "ict:{p}/nope.npz", "--out", "{p}/o.png"], "nope.npz"),
    ("mesh: output under a file", ["mesh", "--out", "{p}/afile/head.obj"], "afile"),
    ("mesh: unknown format", ["mesh", "--out", "{p}/head.txt"], "head.txt"),
    # synth
    ("synth: too few frames", ["synth", "--frames", "5", "--out", "{p}/s"], "--frames"),
    ("synth: size out of range", ["synth", "--size", "8", "--out", "{p}/s"], "--size"),
    ("synth: existing output", ["synth", "--frames", "10", "--size", "16", "--out", "{p}/existing_dataset"],
     "existing_dataset"),
    ("synth: background nan", ["synth", "--background", "nan", "0", "0", "--out", "{p}/s"], "--background"),
    # dataset
    ("dataset: missing", ["dataset", "{p}/nope"], "nope"),
    ("dataset: empty folder", ["dataset", "{p}/empty_dir"], "empty_dir"),
    ("dataset: a file", ["dataset", "{p}/afile"], "afile"),
    ("dataset: truncated image", ["dataset", "{p}/capture"], "0.png"),
    # track
    ("track: missing video", ["track", "{p}/nope.mp4", "--out", "{p}/t"], "nope.mp4"),
    ("track: not a video", ["track", "{p}/text.mp4", "--out", "{p}/t"], "text.mp4"),
    ("track: existing output", ["track", "{p}/video.mp4", "--out", "{p}/existing_dataset"], "existing_dataset"),
    ("track: fps 0", ["track", "{p}/video.mp4", "--out", "{p}/t", "--fps", "0"], "--fps"),
    ("track: size out of range", ["track", "{p}/video.mp4", "--out", "{p}/t", "--size", "4"], "--size"),
    # train
    ("train: missing dataset", ["train", "{p}/nope", "--out", "{p}/a"], "nope"),
    ("train: empty dataset", ["train", "{p}/empty_dir", "--out", "{p}/a"], "empty_dir"),
    ("train: truncated image", ["train", "{p}/capture", "--out", "{p}/a", "--steps", "1"], "0.png"),
    ("train: lr nan", ["train", "{p}/capture", "--out", "{p}/a", "--lr", "nan"], "--lr"),
    ("train: frames per step 0", ["train", "{p}/capture", "--out", "{p}/a", "--frames-per-step", "0"],
     "--frames-per-step"),
    ("train: steps negative", ["train", "{p}/capture", "--out", "{p}/a", "--steps", "-5"], "--steps"),
    ("train: out is a file", ["train", "{p}/capture", "--out", "{p}/afile"], "afile"),
    ("train: into an avatar", ["train", "{p}/capture", "--out", "{p}/avatar"], "avatar"),
    ("train: bad effects", ["train", "{p}/capture", "--out", "{p}/a", "--effects", "glitter"], "glitter"),
    # eval / render / turntable
    ("eval: missing avatar", ["eval", "{p}/nope", "{p}/capture", "--out", "{p}/e"], "nope"),
    ("eval: broken avatar.json", ["eval", "{p}/broken_avatar", "{p}/capture", "--out", "{p}/e"], "avatar.json"),
    ("eval: every 0", ["eval", "{p}/avatar", "{p}/capture", "--every", "0"], "--every"),
    ("eval: truncated image", ["eval", "{p}/avatar", "{p}/capture", "--out", "{p}/e"], "0.png"),
    ("render: missing avatar", ["render", "{p}/nope", "--out", "{p}/r.png"], "nope"),
    ("render: empty folder", ["render", "{p}/empty_dir", "--out", "{p}/r.png"], "empty_dir"),
    ("render: size 0", ["render", "{p}/avatar", "--size", "0"], "--size"),
    ("render: controls a list", ["render", "{p}/avatar", "--controls", "{p}/list.json", "--out", "{p}/r.png"],
     "list.json"),
    ("render: output under a file", ["render", "{p}/avatar", "--out", "{p}/afile/r.png", "--size", "16"], "afile"),
    ("turntable: not an mp4", ["turntable", "{p}/avatar", "--out", "{p}/t.avi"], "t.avi"),
    ("turntable: frames 0", ["turntable", "{p}/avatar", "--frames", "0"], "--frames"),
    ("turntable: zoom 0", ["turntable", "{p}/avatar", "--zoom", "0"], "--zoom"),
    ("turntable: fps 0", ["turntable", "{p}/avatar", "--fps", "0"], "--fps"),
    ("turntable: sweep 200", ["turntable", "{p}/avatar", "--sweep-deg", "200"], "--sweep-deg"),
    ("turntable: broken avatar.json", ["turntable", "{p}/broken_avatar", "--out", "{p}/t.mp4"], "avatar.json"),
    ("prior-train: missing corpus", ["prior-train", "{p}/nope", "--out", "{p}/pr"], "nope"),
    ("prior-train: a corpus without captures", ["prior-train", "{p}/empty_dir", "--out", "{p}/pr"], "empty_dir"),
    ("prior-train: into an avatar", ["prior-train", "{p}", "--out", "{p}/avatar"], "avatar"),
    ("prior-train: lr 0", ["prior-train", "{p}", "--out", "{p}/pr", "--lr", "0"], "--lr"),
    ("prior-train: bad effects", ["prior-train", "{p}", "--out", "{p}/pr", "--effects", "glitter"], "glitter"),
    ("corpus: held-out seeds", ["corpus", "--first", "999", "--identities", "2", "--out", "{p}/c"], "--first"),
    ("corpus: unknown scene", ["corpus", "--scenes", "glitter", "--out", "{p}/c"], "glitter"),
    ("corpus: existing output", ["corpus", "--out", "{p}/existing_dataset"], "existing_dataset"),
    ("personalize: missing scan", ["personalize", "{p}/nope", "--prior", "{p}/avatar", "--out", "{p}/me"], "nope"),
    ("personalize: truncated image", ["personalize", "{p}/capture", "--prior", "{p}/avatar", "--out", "{p}/me"],
     "0.png"),
    ("personalize: existing output", ["personalize", "{p}/capture", "--out", "{p}/existing_dataset"],
     "existing_dataset"),
    ("animate: missing animation", ["animate", "{p}/avatar", "{p}/nope.json", "--out", "{p}/a.mp4"], "nope.json"),
    ("animate: animation truncated", ["animate", "{p}/avatar", "{p}/truncated.json", "--out", "{p}/a.mp4"],
     "truncated.json"),
    ("animate: animation a list", ["animate", "{p}/avatar", "{p}/list.json", "--out", "{p}/a.mp4"], "list.json"),
    ("reenact: missing video", ["reenact", "{p}/avatar", "{p}/nope.mp4", "--out", "{p}/r.mp4", "--landmarker",
                                "{p}/lm.task"], "nope.mp4"),
    ("reenact: not an mp4", ["reenact", "{p}/avatar", "{p}/nope.mp4", "--out", "{p}/r.gif"], "r.gif"),
    ("reenact: broken avatar.json", ["reenact", "{p}/broken_avatar", "{p}/nope.mp4", "--out", "{p}/r.mp4"],
     "avatar.json"),
    ("reenact: size 0", ["reenact", "{p}/avatar", "{p}/nope.mp4", "--size", "0"], "--size"),
    ("export-mesh: unknown format", ["export-mesh", "{p}/avatar", "--out", "{p}/head.stl"], "head.stl"),
    ("export-mesh: broken avatar.json", ["export-mesh", "{p}/broken_avatar", "--out", "{p}/h.ply"], "avatar.json"),
    ("export-mesh: resolution 2", ["export-mesh", "{p}/avatar", "--resolution", "2"], "--resolution"),
    ("export: broken avatar.json", ["export", "{p}/broken_avatar", "--out", "{p}/a.glb"], "avatar.json"),
    ("export: missing animation", ["export", "{p}/avatar", "--animation", "{p}/nope.json", "--out", "{p}/a.glb"],
     "nope.json"),
    ("export: texture size 8", ["export", "{p}/avatar", "--texture-size", "8"], "--texture-size"),
    ("live: no camera", ["live", "{p}/avatar", "--source", "7"], "camera 7"),
    ("live: missing video", ["live", "{p}/avatar", "--source", "{p}/nope.mp4"], "nope.mp4"),
    ("live: not an avatar", ["live", "{p}/capture", "--source", "7"], "capture"),
    ("bench: size 0", ["bench", "--size", "0", "--out", "{p}/b"], "--size"),
    ("bench: into a folder of the user's", ["bench", "--out", "{p}/existing_dataset", "--quick"], "existing_dataset"),
    ("bench: missing dataset", ["bench", "--dataset", "{p}/nope", "--out", "{p}/b", "--train-seconds", "0"],
     "nope"),
]


@pytest.mark.gl
@pytest.mark.parametrize(("name", "argv", "word"), CASES, ids=[c[0] for c in CASES])
def test_bad_input(name, argv, word, place, capsys):
    before = snapshot(place)
    args = [a.replace("{p}", str(place)) for a in argv]
    assert main(args) == 2, name
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and word in err[0], (name, err)
    after = snapshot(place)
    assert {k: v for k, v in after.items() if k in before} == before, name  # nothing that was there changed


def test_the_table_covers_every_command():
    from app.commands import COMMANDS

    covered = {argv[0] for _, argv, _ in CASES}
    assert covered == {c.name for c in COMMANDS} - {"studio"}, covered  # the studio: tests/app/studio
    print(f"{len(CASES)} bad-input cases over {len(covered)} commands")


@pytest.mark.gl
def test_outputs_never_overwrite_a_users_other_files(place, tmp_path, capsys):
    """eval into a folder of the user's, a turntable whose PNG folder holds the user's files: refused; a turntable
    into a fresh place writes an ordinary mp4 and nothing else beside it."""
    import stat

    mine = tmp_path / "photos"
    mine.mkdir()
    (mine / "test_0000.jpg").write_bytes(b"mine")
    assert main(["eval", str(place / "avatar"), str(place / "capture"), "--out", str(mine)]) == 2
    assert "eval did not write" in capsys.readouterr().err
    assert main(["turntable", str(place / "avatar"), "--out", str(tmp_path / "photos.mp4"), "--frames", "2",
                 "--size", "16", "--preset", "draft"]) == 2
    assert "other files" in capsys.readouterr().err and (mine / "test_0000.jpg").read_bytes() == b"mine"
    out = tmp_path / "fresh" / "turn.mp4"
    assert main(["turntable", str(place / "avatar"), "--out", str(out), "--frames", "2", "--size", "16",
                 "--preset", "draft", "--no-pngs"]) == 0
    assert stat.S_IMODE(out.stat().st_mode) == 0o644 and sorted(p.name for p in out.parent.iterdir()) == ["turn.mp4"]

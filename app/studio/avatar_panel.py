"""The Avatar panel: open an avatar folder (typed, from a file dialog, or from the recent list); what it is:
head model, effect set, training provenance and measured metrics."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from imgui_bundle import imgui, portable_file_dialogs

from app.studio.actions import ClearMessages, OpenAvatar, Report
from app.studio.context import PanelContext
from app.studio.session import recent_folders


class PanelState:
    path = ""
    dialog = None
    browsing: Path | None = None
    """The folder the built-in browser shows (None: closed)."""


DIALOG_PROGRAMS = ("zenity", "matedialog", "qarma", "kdialog")
"""What the desktop's file dialog runs on Linux (portable-file-dialogs); other systems have theirs built in."""


def system_dialog_available() -> bool:
    return sys.platform != "linux" or any(shutil.which(p) for p in DIALOG_PROGRAMS)


def subfolders(folder: Path) -> list[Path]:
    """The folders in `folder`, sorted, hidden ones left out (an unreadable folder has none)."""
    try:
        return sorted((p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")),
                      key=lambda p: p.name.lower())
    except OSError:
        return []


def draw_browser(act) -> None:
    """The built-in folder browser (where the desktop has no file dialog): up, into a folder, open an avatar."""
    here = PanelState.browsing
    imgui.text_wrapped(str(here))
    if imgui.button("Up") and here.parent != here:
        PanelState.browsing = here.parent
    imgui.same_line()
    if imgui.button("Close"):
        PanelState.browsing = None
        return
    if imgui.begin_child("folders", imgui.ImVec2(-1, 160), imgui.ChildFlags_.borders):
        for folder in subfolders(here):
            avatar = (folder / "avatar.json").is_file()
            if imgui.selectable(f"{folder.name}  [avatar: open]" if avatar else f"{folder.name}/", False)[0]:
                if avatar:
                    PanelState.path, PanelState.browsing = str(folder), None
                    act(OpenAvatar(folder))
                else:
                    PanelState.browsing = folder
    imgui.end_child()


def draw(ctx: PanelContext) -> None:
    s, act = ctx.session, ctx.act
    imgui.set_next_item_width(200)
    _, PanelState.path = imgui.input_text("##folder", PanelState.path)
    imgui.same_line()
    if imgui.button("Open") and PanelState.path:
        act(OpenAvatar(Path(PanelState.path.strip())))
    imgui.same_line()
    if imgui.button("Browse...") and PanelState.dialog is None:
        if not system_dialog_available():  # no dialog program on this desktop: the built-in browser
            PanelState.browsing = Path(PanelState.path.strip() or ".").resolve()
            if not PanelState.browsing.is_dir():
                PanelState.browsing = Path.cwd()
        else:
            try:
                PanelState.dialog = portable_file_dialogs.select_folder("Open an avatar folder")
            except Exception as e:  # the dialog failed to start: the built-in browser, and why
                act(Report(f"file dialog unavailable ({e}): using the studio's own folder browser"))
                PanelState.browsing = Path.cwd()
    if PanelState.browsing is not None:
        draw_browser(act)
    if PanelState.dialog is not None and PanelState.dialog.ready():
        chosen = PanelState.dialog.result()
        PanelState.dialog = None
        if chosen:
            PanelState.path = chosen
            act(OpenAvatar(Path(chosen)))
    recent = recent_folders()
    if recent and imgui.begin_combo("recent", "open a recent avatar"):
        for folder in recent:
            if imgui.selectable(folder, False)[0]:
                PanelState.path = folder
                act(OpenAvatar(Path(folder)))
        imgui.end_combo()
    imgui.separator()
    if s.opening is not None:
        imgui.text(f"opening {s.opening.name}...")
    if s.avatar is None:
        if s.opening is None:
            imgui.text("No avatar open.")
    else:
        m = s.files.meta
        prov = m.get("provenance", {})
        imgui.text(f"{s.name}  ({s.avatar.name})")
        imgui.text(f"head model: {s.avatar.head_model.name}")
        imgui.text(f"effects: {s.avatar.describe_effects()}")
        imgui.text(f"trained {prov.get('steps', '?')} steps, {prov.get('seconds', 0) / 60:.1f} min")
        imgui.text_wrapped(f"on {prov.get('dataset', '?')}")
        if s.files.metrics:
            met = s.files.metrics
            imgui.text(f"test PSNR {met.get('psnr', float('nan')):.2f} dB, SSIM {met.get('ssim', float('nan')):.3f}")
            if "normal_deg" in met:
                median = f", median {met['normal_median_deg']:.1f}" if "normal_median_deg" in met else ""
                imgui.text(f"normal error {met['normal_deg']:.1f} deg{median}")
    for e in s.errors[-3:]:
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.35, 1.0), "")
        imgui.same_line()
        imgui.push_text_wrap_pos(0)
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.35, 1.0), e)
        imgui.pop_text_wrap_pos()
    if s.errors and imgui.small_button("clear messages"):
        act(ClearMessages())

"""The Quality panel: the presets (chosen by `avatar-studio bench` from the Pareto front of error against time
and stored with the avatar, else the built-in ones), each with the figures the bench measured and its time per
frame and error against `final` measured on the open avatar when it loads; which pass the viewport refines to
while the controls rest."""

from __future__ import annotations

from imgui_bundle import imgui

from app.studio.actions import RefineTo
from app.studio.context import PanelContext
from models.avatars.quality import PRESET_NAMES


def draw(ctx: PanelContext) -> None:
    fig = ctx.worker.figures
    avatar = ctx.session.avatar
    if avatar is None:
        imgui.text_disabled(ctx.session.absent("No avatar open."))
        return
    presets = avatar.presets
    imgui.text("refine to:")
    for name in PRESET_NAMES:
        imgui.same_line()
        if imgui.radio_button(name, ctx.session.display.refine_to == name):
            ctx.act(RefineTo(name))
    benched = any(p.ms is not None for p in presets.values())
    flags = imgui.TableFlags_.borders | imgui.TableFlags_.row_bg
    # With the bench's figures: those (time, error against final, test PSNR) and this machine's time now;
    # without: the time and error measured when the avatar opened.
    columns = ["preset", "setting"] + (["ms", "vs final", "test dB", "ms now"] if benched else ["ms", "vs final"])
    if imgui.begin_table("presets", len(columns), flags):
        for h in columns:
            imgui.table_setup_column(h)
        imgui.table_headers_row()
        for name in PRESET_NAMES:
            p = presets[name]
            now = f"{fig.ms[name]:.0f}" if name in fig.ms else "..."
            imgui.table_next_row()
            cells = [name, p.quality.describe().replace(" samples", "")]
            if benched:
                cells += [_num(p.ms, "{:.0f}"), _db(p.psnr_vs_final, name), _num(p.psnr, "{:.2f}"), now]
            else:
                cells += [now, _db(fig.psnr_vs_final.get(name), name)]
            for c in cells:
                imgui.table_next_column()
                imgui.text(c)
            if benched and p.face_mse is not None and imgui.is_item_hovered():
                imgui.set_tooltip(f"FaceMSE {p.face_mse:.5f} on the capture's held-out frames")
        imgui.end_table()
    imgui.text_wrapped(f"ms now: measured on this avatar at {fig.size_px or '...'} px (its capture's size) when it "
                       "opened (median of 3 renders, this machine).")
    if fig.march:
        imgui.text_wrapped(f"march: {fig.march}" + ("" if fig.march == "C" else ": slower; install a C compiler"))
    measured = avatar.presets_measured
    if benched:
        where = f"{measured.get('image_px', '?')} px, {measured.get('machine', 'machine unknown')}"
        imgui.text_wrapped(f"bench: chosen from the Pareto front by `avatar-studio bench` ({where}); test PSNR and "
                           "FaceMSE on the capture's held-out frames.")
    else:
        imgui.text_wrapped("Built-in presets: run `avatar-studio bench` to measure this avatar's trade-off and "
                           "choose them from its Pareto front.")


def _num(v: float | None, fmt: str) -> str:
    return "" if v is None else fmt.format(v)


def _db(v: float | None, name: str) -> str:
    if v is None:
        return ""
    return "reference" if name == "final" or v == float("inf") else f"{v:.1f} dB"

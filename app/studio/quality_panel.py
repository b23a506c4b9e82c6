"""The Quality panel: the presets, each with its time per frame and its error against `final`, measured on
the open avatar when it loads; which pass the viewport refines to while the controls rest."""

from __future__ import annotations

from typing import TYPE_CHECKING

from imgui_bundle import imgui

from app.turntable import PRESETS

if TYPE_CHECKING:
    from app.studio.app import Studio


def draw(studio: Studio) -> None:
    fig = studio.worker.figures
    if studio.session.avatar is None:
        imgui.text("No avatar open.")
        return
    imgui.text("refine to:")
    for name in PRESETS:
        imgui.same_line()
        if imgui.radio_button(name, studio.refine_to == name):
            studio.refine_to = name
            studio.dirty = True
    flags = imgui.TableFlags_.borders | imgui.TableFlags_.row_bg
    if imgui.begin_table("presets", 4, flags):
        for h in ("preset", "size, samples", "ms / frame", "PSNR vs final"):
            imgui.table_setup_column(h)
        imgui.table_headers_row()
        for name, (scale, samples) in PRESETS.items():
            imgui.table_next_row()
            imgui.table_next_column()
            imgui.text(name)
            imgui.table_next_column()
            imgui.text(f"{scale:g}x, {samples}")
            imgui.table_next_column()
            imgui.text(f"{fig.ms[name]:.0f}" if name in fig.ms else "measuring...")
            imgui.table_next_column()
            v = fig.psnr_vs_final.get(name)
            imgui.text("reference" if name == "final" and v is not None else "" if v is None else f"{v:.1f} dB")
        imgui.end_table()
    imgui.text_wrapped("Measured on this avatar at 128 px (median of 3 renders, this machine).")

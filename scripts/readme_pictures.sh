#!/usr/bin/env bash
# The README's head pictures, made with the commands the README lists. Needs ../shared for the ICT head.
set -euo pipefail
cd "$(dirname "$0")/.."
S=".venv/bin/avatar-studio preview --size 256 256"
ICT="ict:../shared/data/ict_facekit/ict_head.npz"
T=$(mktemp -d)
$S --out $T/b1.png
$S --controls resources/controls/jaw_open.json --out $T/b2.png
$S --expression blink_L=1 blink_R=1 smile_L=0.6 smile_R=0.6 --out $T/b3.png
$S --controls resources/controls/head_turned.json --out $T/b4.png
$S --pass normals --yaw-deg -30 --out $T/b5.png
$S --pass wireframe --landmarks --out $T/b6.png
$S --head $ICT --out $T/i1.png
$S --head $ICT --expression jawOpen=0.7 --out $T/i2.png
$S --head $ICT --expression eyeBlink_L=1 eyeBlink_R=1 mouthSmile_L=0.6 mouthSmile_R=0.6 --out $T/i3.png
$S --head $ICT --controls resources/controls/head_turned.json --out $T/i4.png
$S --head $ICT --pass normals --yaw-deg -30 --out $T/i5.png
$S --head $ICT --pass shadow --out $T/i6.png
.venv/bin/python scripts/contact_sheet.py docs/img/builtin_head.png $T/b{1,2,3,4,5,6}.png
.venv/bin/python scripts/contact_sheet.py docs/img/ict_head.png $T/i{1,2,3,4,5,6}.png
rm -r "$T"
echo "wrote docs/img/builtin_head.png docs/img/ict_head.png"

#!/bin/sh
# Issue 42: render the fixed scene files of this folder (and issue 26's two) into transport stores in
# OUT_DIR, at the projector / camera rows the study measures.  Regenerable, not committed (a few hundred MB);
# about 40 minutes on the shared 2 cores.  Then: tools/demux_weights_study.py --stores OUT_DIR/*.zarr ...
set -e
OUT=${1:?usage: sh tools/demux_weights_scenes/render.sh OUT_DIR}
PY=${PY:-.venv/bin/python}
HERE=$(dirname "$0")
mkdir -p "$OUT"
for geo in "96 64 4096" "360 128 2048" "720 128 2048"; do
  set -- $geo
  for s in corner_wall_floor mirror_sphere media_milk_marble media_soap_skin corner_sphere_block; do
    [ -e "$OUT/${s}_$1_$2.zarr" ] || nice -n 10 $PY -m planeray.cli render "$HERE/$s.xml" \
      --out "$OUT/${s}_$1_$2.zarr" --rows "$1" --size "$2" "$2" --spp "$3"
  done
done
for s in room_mirror_block box_interreflections; do  # issue 26's, as its table rendered them
  [ -e "$OUT/i26_${s}_720_32.zarr" ] || nice -n 10 $PY -m planeray.cli render "$HERE/../demux_auto_scenes/$s.xml" \
    --out "$OUT/i26_${s}_720_32.zarr" --rows 720 --size 32 32 --spp 64
done

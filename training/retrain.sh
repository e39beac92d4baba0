#!/usr/bin/env bash
# Retrains one tracking mode's shipped networks end to end (the commands of
# training/README.md, in order): ego shards, EgoNet, three fold EgoNets and their fusion
# shards, validation fusion shards, gate + fusion, the live (lookahead 0) variant, and ships
# them into models/. Usage: training/retrain.sh 3|1   (run from the repository root; both
# modes can run at once, one thread each).
#
# Environment: EGOEXO (the release CLI), PY (python with training/requirements.txt),
# LIB (the motion library), TRAIN / VAL (subjects), FOLD_STEPS, EGO_STEPS, FUSION_STEPS.
set -euo pipefail
T=${1:?usage: retrain.sh 3|1}
EGOEXO=${EGOEXO:-target/release/egoexo}
PY=${PY:-target/py/bin/python}
LIB=${LIB:-data/cmu-all.safetensors}
TRAIN=${TRAIN:-1,2,3,6,7,8,9,10,11,12,14,35,55,93,105,131,135}
VAL=${VAL:-5,16}
EGO_STEPS=${EGO_STEPS:-2500}
# Fold EgoNets as long as the shipped one: the fusion then learns on coarse poses of the
# quality it gets at run time (1,000 steps gave 3-point ego-exo 8.17 cm, 2,500 steps 8.05).
FOLD_STEPS=${FOLD_STEPS:-2500}
FUSION_STEPS=${FUSION_STEPS:-2000}
# 3-point shards alternate wrist devices and hand tracking (wrists that come and go).
if [ "$T" = 3 ]; then TRACK=3-mixed; else TRACK=1; fi
export PYTHONPATH=training
log() { echo "[$(date +%H:%M:%S)] mode $T: $*"; }

log "ego shards"
$EGOEXO synth --lib $LIB --subjects $TRAIN --observers 3 --tracking $TRACK --seed 7 --shards ego \
    --simulations 2 --stride 24 -o data/shards/ego$T
$EGOEXO synth --lib $LIB --subjects $VAL --observers 3 --tracking $TRACK --seed 8 --shards ego \
    --simulations 2 --stride 48 --no-mirror -o data/shards/val-ego$T

log "EgoNet"
$PY -m egoexo_train.train --stage ego --shards data/shards/ego$T --val data/shards/val-ego$T \
    --out runs/ego$T --steps $EGO_STEPS --eval-every 500 --threads 1
$PY -m egoexo_train.ship --ego runs/ego$T/ego.pt --egonet-only runs/ego$T/egonet.onnx

for k in 0 1 2; do
  log "fold EgoNet $k"
  $PY -m egoexo_train.train --stage ego --shards data/shards/ego$T --val data/shards/val-ego$T \
      --out runs/ego$T-x$k --exclude-fold $k/3 --steps $FOLD_STEPS --eval-every 500 --threads 1
  $PY -m egoexo_train.ship --ego runs/ego$T-x$k/ego.pt --egonet-only runs/ego$T-x$k/egonet.onnx
  $EGOEXO synth --lib $LIB --subjects $TRAIN --observers 3 --tracking $TRACK --seed 7 --shards fusion \
      --egonet runs/ego$T-x$k/egonet.onnx --simulations 2 --stride 24 --fold $k/3 -o data/shards/fusion$T-f$k
done
$EGOEXO synth --lib $LIB --subjects $VAL --observers 3 --tracking $TRACK --seed 8 --shards fusion \
    --egonet runs/ego$T/egonet.onnx --simulations 2 --stride 48 --no-mirror -o data/shards/val-fusion$T

FUSION_ARGS="--hidden 96 --spatial-layers 1 --temporal-layers 2 --velocity-weight 5 --output-smoothing 2 \
    --exo-smoothing 2 --exo-fade --gate-aux-weight 0 --threads 1"
log "gate + fusion"
$PY -m egoexo_train.train --stage fusion --shards data/shards/fusion$T-f0 data/shards/fusion$T-f1 data/shards/fusion$T-f2 \
    --val data/shards/val-fusion$T --out runs/fusion$T --steps $FUSION_STEPS --eval-every 500 $FUSION_ARGS
log "live variant (lookahead 0)"
$PY -m egoexo_train.train --stage fusion --shards data/shards/fusion$T-f0 data/shards/fusion$T-f1 data/shards/fusion$T-f2 \
    --val data/shards/val-fusion$T --out runs/fusion$T-live0 --steps $FUSION_STEPS --eval-every 500 $FUSION_ARGS \
    --readout-lookahead 0 --readout-weight 1
log "done"

#!/bin/bash
# DAgger for the pair network: roll the network out (12 runs of 16 robots), relabel its states
# with the expert, detect, retrain on everything so far, score on teams-generalist.
# Usage: pairs_dagger.sh WORK START_MODEL TRAIN.npz TRAIN-det.npy VAL.npz VAL-det.npy
set -euo pipefail
D=$(cd "$(dirname "$0")" && pwd); P=${PYTHON:-.venv/bin/python}
W=$1; M=$2; TR=$3; TD=$4; VA=$5; VD=$6
for it in 1 2 3; do
  RECORD=$W/dag$it.npz FIRST=$((100 + it * 20)) $P "$D/pairs_closedloop.py" "$D/collect16.toml" 16 12 7001 "$M"
  $P "$D/pairs_detectall.py" "$W/dag$it.npz" "$W/dag$it-det.npy" 8
  TR=$TR,$W/dag$it.npz; TD=$TD,$W/dag$it-det.npy
  MAIN=0.1 EPOCHS=30 SAVE=$W/pair-dag$it.pt TRAIN=$TR TRAIN_DET=$TD VAL=$VA VAL_DET=$VD VAL_NOISE=0 \
    $P "$D/pairs_pairnet.py" | grep detected | tail -1
  M=$W/pair-dag$it.pt
  $P "$D/pairs_closedloop.py" scenarios/teams-generalist.toml 16 6 7 "$M"
done

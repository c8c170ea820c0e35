#!/bin/bash
# Issue 32, item 7: the SDE, MOPO's ensemble and a linear model on Gymnasium's
# swimmer, ant (random data) and inverted pendulum (a medium dataset from an
# online SAC run): open-loop prediction error and the calibration report.
cd "$(dirname "$0")/.."
B=${NUNO_TRAINER:-target/release/nuno-trainer}
O=runs/systems
L=$O/log
stamp() { echo "$1 $(date -u +%FT%TZ) load $(cut -d' ' -f1-3 /proc/loadavg)" >>$L; }
measure() {  # task train-data eval-data
  local t=$1 train=$2 eval=$3
  stamp "fit-model $t"
  $B fit-model --task $t --dataset $train --out $O/$t/sde --max-steps 5000 --eval-every 250 --seed 0 >>$L 2>&1
  stamp "fit-ensemble $t"
  $B fit-ensemble --task $t --dataset $train --out $O/$t/ensemble --max-epochs 10 --seed 0 >>$L 2>&1
  stamp "analyze $t"
  $B analyze --model nuno=$O/$t/sde --model mopo=$O/$t/ensemble --linear-baseline --dataset $eval \
    --horizon 10 --windows 500 --out $O/$t/analysis >>$L 2>&1
  $B eta-report --model $O/$t/sde --dataset $eval >$O/$t/eta-report.txt 2>&1
  stamp "done $t"
}
for t in swimmer ant; do
  stamp "data $t"
  $B dataset generate --task $t --kind random --transitions 200000 --seed 0 --out data/$t-random.hdf5 >>$L 2>&1
  $B dataset generate --task $t --kind random --transitions 50000 --seed 1 --out data/$t-random-eval.hdf5 >>$L 2>&1
  measure $t data/$t-random.hdf5 data/$t-random-eval.hdf5
done
t=invertedpendulum
stamp "online-sac $t"
$B collect online-sac --task $t --steps 30000 --seed 0 --checkpoint-every 2000 --out $O/$t-sac >>$L 2>&1
$B collect select --run $O/$t-sac >>$L 2>&1
$B dataset generate --task $t --kind medium --transitions 200000 --seed 0 --out data/$t-medium.hdf5 >>$L 2>&1
$B dataset generate --task $t --kind medium --transitions 50000 --seed 1 --out data/$t-medium-eval.hdf5 >>$L 2>&1
measure $t data/$t-medium.hdf5 data/$t-medium-eval.hdf5
stamp "systems done"

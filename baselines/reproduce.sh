#!/usr/bin/env bash
# Reproduces results/baselines/ (the expert-vs-learned benchmark) from scratch: about 3.3 h on the project's
# 2-core machine. Run from the repository root after `make test` (which installs the [rl] extra):
#     bash baselines/reproduce.sh            # all stages, in order
#     bash baselines/reproduce.sh bench      # one stage: corridor | others | record | bc | publish | reward | bench | rllib | rllib_publish
# Every learned policy trains with the benchmark's noise (5 % thrust noise, objects start within 5 cm),
# seed 0 and the hyperparameters in baselines/hyperparams/. Training runs are bounded both by --timesteps
# and by a wall-clock budget (--max-minutes), two side by side (one per core); each run's train.json
# records the steps it reached. QUICK=1 rehearses the chain in ~10 minutes with a few thousand steps, writing to
# runs-quick/ instead of results/baselines/ (its numbers are meaningless).
set -euo pipefail
BIN=${BIN:-.venv/bin}
NOISE="--thrust-noise 0.05 --initial-position-noise-m 0.05"
SCENARIOS="corridor obstacle_avoidance throw_and_catch_exp"
export OMP_NUM_THREADS=1   # one core per training run
if [[ "${QUICK:-0}" == 1 ]]; then
    PPO_LONG=2048; PPO_SHORT=2048; SAC_STEPS=1500; LONG=5; SHORT=5; EPISODES=2; DEMOS=2; EVAL_PPO=1024; EVAL_SAC=500; PPO_REWARD=2048
    RUNS=runs-quick; RESULTS=runs-quick/results; DATASETS=runs-quick/datasets
else
    PPO_LONG=2000000; PPO_SHORT=1000000; SAC_STEPS=300000; LONG=58; SHORT=14; EPISODES=20; DEMOS=30
    EVAL_PPO=50000; EVAL_SAC=20000; PPO_REWARD=600000; RUNS=runs; RESULTS=results/baselines; DATASETS=datasets
fi
train() { "$BIN/impact-env" train --runs-dir "$RUNS" "$@" $NOISE --quiet; }  # --out names the run folder
side_by_side() {  # the two training commands given as strings, one per core; fails if either fails
    $1 & local a=$!
    $2 & local b=$!
    wait $a; wait $b
}

corridor() {  # the full runs: PPO and SAC for up to LONG minutes each, side by side
    side_by_side "train ppo corridor --timesteps $PPO_LONG --n-envs 2 --max-minutes $LONG --eval-freq $EVAL_PPO" \
                 "train sac corridor --timesteps $SAC_STEPS --max-minutes $LONG --eval-freq $EVAL_SAC"
}

others() {  # the other two scenarios: up to SHORT minutes each
    for s in obstacle_avoidance throw_and_catch_exp; do
        side_by_side "train ppo $s --timesteps $PPO_SHORT --n-envs 2 --max-minutes $SHORT --eval-freq $EVAL_PPO" \
                     "train sac $s --timesteps $SAC_STEPS --max-minutes $SHORT --eval-freq $EVAL_SAC"
    done
}

record() {  # expert demonstrations as Minari datasets
    for s in $SCENARIOS; do
        "$BIN/impact-env" record $s --episodes $DEMOS $NOISE --out "$DATASETS"
    done
}

bc() {  # behaviour cloning from them
    for s in $SCENARIOS; do
        "$BIN/impact-env" bc $s --dataset "$DATASETS" --runs-dir "$RUNS"
    done
}

publish() {  # the trained models (no checkpoints) and the learning curves
    for a in ppo sac bc; do
        for s in $SCENARIOS; do
            mkdir -p "$RESULTS/models/${a}_$s"
            cp "$RUNS/${a}_${s}_s0"/{model.zip,vecnormalize.json,train.json} "$RESULTS/models/${a}_$s/"
        done
    done
    for s in $SCENARIOS; do
        "$BIN/impact-env" curves "$RUNS/ppo_${s}_s0" "$RUNS/sac_${s}_s0" --title "$s" --plot "$RESULTS/curves_$s.png" \
            --table "$RESULTS/training_$s.md"
    done
}

reward() {  # the corridor reward investigation: PPO with the "conjuncts" reward, then also with quiet exploration
    local quiet=baselines/hyperparams/experiments/ppo_quiet.yml
    side_by_side "train ppo corridor --reward-mode conjuncts --timesteps $PPO_REWARD --n-envs 2 --eval-freq $EVAL_PPO --out $RUNS/conjuncts/ppo_corridor_s0" \
                 "train ppo corridor --reward-mode conjuncts --hyperparams $quiet --timesteps $PPO_REWARD --n-envs 2 --eval-freq $EVAL_PPO --out $RUNS/quiet/ppo_corridor_s0"
    "$BIN/impact-env" curves "$RUNS/ppo_corridor_s0" "$RUNS/conjuncts/ppo_corridor_s0" "$RUNS/quiet/ppo_corridor_s0" \
        "$RUNS/sac_corridor_s0" --labels "PPO dense,PPO conjuncts,PPO conjuncts + quiet exploration,SAC dense" \
        --title "corridor: reward investigation" --plot "$RESULTS/reward_investigation.png" --table "$RESULTS/reward_investigation.md"
}

bench() {
    local m="$RESULTS/models"
    "$BIN/impact-env" bench corridor,obstacle_avoidance,throw_and_catch_exp --episodes $EPISODES $NOISE --workers 2 \
        --controllers "expert,ppo:$m/ppo_{scenario}/model.zip,sac:$m/sac_{scenario}/model.zip,bc:$m/bc_{scenario}/model.zip,random,zero" \
        --out "$RESULTS"
}

rllib() {  # RLlib's multi-agent PPO (independent policies, 2 env runners) on throw_and_catch_exp, SB3's budget there
    local run="$RUNS/rllib_ppo_throw_and_catch_exp_independent_s0" m="$RESULTS/models"
    "$BIN/impact-env" train ppo throw_and_catch_exp --engine rllib --policies independent --env-runners 2 \
        --runs-dir "$RUNS" --timesteps $PPO_SHORT --max-minutes $SHORT --eval-freq $EVAL_PPO $NOISE --quiet
}

rllib_publish() {  # its export (pickle-free), learning curve and bench beside SB3's PPO, the expert and the floor
    local run="$RUNS/rllib_ppo_throw_and_catch_exp_independent_s0" m="$RESULTS/models"
    mkdir -p "$m/rllib_ppo_throw_and_catch_exp"
    cp "$run/checkpoint/policy/"* "$m/rllib_ppo_throw_and_catch_exp/"   # the pickle-free export only
    cp "$run/train.json" "$run/progress.csv" "$m/rllib_ppo_throw_and_catch_exp/"
    local runs="$run" labels="RLlib PPO (independent policies)"
    if [[ -d "$RUNS/ppo_throw_and_catch_exp_s0" ]]; then
        runs="$RUNS/ppo_throw_and_catch_exp_s0 $run"; labels="SB3 PPO (one central policy),$labels"
    fi
    "$BIN/impact-env" curves $runs --labels "$labels" --title "throw_and_catch_exp: SB3 and RLlib" \
        --plot "$RESULTS/curves_rllib_throw_and_catch_exp.png" --table "$RESULTS/training_rllib_throw_and_catch_exp.md"
    [[ "${QUICK:-0}" == 1 ]] || cp "$RESULTS/curves_rllib_throw_and_catch_exp.png" docs/img/rllib_curves_throw_and_catch_exp.png
    "$BIN/impact-env" bench throw_and_catch_exp --episodes $EPISODES $NOISE --workers 2 \
        --controllers "expert,ppo:$m/ppo_{scenario}/model.zip,rllib:rllib:$m/rllib_ppo_{scenario},random,zero" \
        --out "$RESULTS/rllib"
}

stages=("$@")
[[ ${#stages[@]} -eq 0 ]] && stages=(corridor others record bc publish reward bench rllib rllib_publish)
for stage in "${stages[@]}"; do
    case $stage in
        corridor|others|record|bc|publish|reward|bench|rllib|rllib_publish) echo "== $stage"; $stage ;;
        *) echo "unknown stage '$stage' (corridor, others, record, bc, publish, reward, bench, rllib, rllib_publish)" >&2; exit 2 ;;
    esac
done

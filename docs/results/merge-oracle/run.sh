#!/bin/bash
# Merge from a non-target lane behind the shield: which of the 200 validation episodes (seeds from 200,000) can be
# solved at all. The published merge-pre60k networks (seeds 0, 1, 2) and the scripted driver drive each episode;
# the ones none of them solves go to oracle.py's search (plans driven on copies of the env). Ran 2026-11-29 at
# revision 08cdee8 (2 min 40 s). Run from the repository root; writes here.
set -e
out=docs/results/merge-oracle
python $out/oracle.py --seed0 200000 --episodes 200 --out $out | tee $out/validation.log
# The same on the 200 test episodes (seeds from 100,000), run 2026-11-29 at revision 092a025 after every choice that
# the validation episodes served had been made (no choice rests on it; it states what the road allows there):
python $out/oracle.py --seed0 100000 --episodes 200 --out $out/test | tee $out/test/test.log

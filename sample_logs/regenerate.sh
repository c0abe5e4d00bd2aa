#!/usr/bin/env bash
# The sample logs are made by altfuse itself; tests/test_simulate.py checks each file against
# the command on its line, byte for byte. Run from the repository's root.
set -euo pipefail
altfuse simulate mission -o sample_logs/mission.bin --seed 0 --force
altfuse simulate paper-a -o sample_logs/paper_a.bin --seed 0 --force
altfuse simulate hover -o sample_logs/hover.bin --seed 0 --force
altfuse simulate mission -o sample_logs/mission_faults.bin --seed 1 --fault gps-glitch --fault rangefinder-dropout --force

"""cdw-twin: the conveyor digital twin (scene, co-simulation, events, ground truth, scores)."""

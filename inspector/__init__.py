"""routefuse inspector: the viser browser UI for stepping the estimator and debugging matches,
and the headless export of tunnel replays."""

"""Training from healthy logs (`logscan train`): `train` fits the trainable detectors and writes
the tables file, `tables` reads, checks and applies it (the pipeline applies it: this package's
`__init__` imports nothing, so the pipeline can use `tables` without `train`), `calibration`
scales the measurement noise to what healthy logs show, `process_noise` fits the process noise,
`tuning` picks thresholds."""

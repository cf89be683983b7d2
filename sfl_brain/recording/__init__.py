"""What a run leaves behind and how it is read back: the records (one row per trial, written in one place),
typed Arrow tables, the Rerun log and its sink, provenance and the safe-learning metrics over the records.

It imports the contract (messages, telemetry, events, status) and the scenario; never a protocol or the runtime.
"""

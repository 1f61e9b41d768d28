"""The estimator's flight recordings: an mcap file per session that survives a kill, and reading it back."""

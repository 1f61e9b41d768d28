"""The estimator node: parameters, the view buffer and its input matching, the running job, diagnostics."""

"""Verification: the case registry, the runner and one module per case family (cases/);
run with `python -m fcm_fsi verify NAME --level quick|full`."""

"""Verification runner: python -m fcm_fsi.verify NAME --level quick|full."""

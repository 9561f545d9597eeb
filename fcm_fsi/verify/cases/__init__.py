"""Verification cases; each module registers its cases with fcm_fsi.verify.registry.register."""

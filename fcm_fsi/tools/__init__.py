"""The commands of ``python -m fcm_fsi`` (fcm_fsi/cli.py), one module each: ``add_arguments(parser)``
declares its options, ``run(args)`` runs it and returns the exit code. They sit above every
physics package and import from them; nothing below imports from here."""

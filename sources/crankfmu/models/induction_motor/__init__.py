"""The induction motor (planetary_drive_friction_clutch.txt): Kloss law or linear law. See README.md."""

"""The planetary clutch drive with friction brakes (planetary_drive_friction_clutch.txt). See README.md."""

"""The twin crank-slider drive of a pipe mill stand (mill_stand_drive_structure.txt). See README.md."""

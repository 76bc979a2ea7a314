"""The rocker impact unit and the crank-rocker hammer (rocker_impact_unit.txt). See README.md."""

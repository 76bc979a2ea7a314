"""The system layer: a scene (components, connections, inputs, master settings), swaps, the
wiring of FMUs into a system, and the file formats a scene is read from and written to (TOML
scene files, SSP archives). `crankfmu.system.load.load_scene(path)` reads either."""

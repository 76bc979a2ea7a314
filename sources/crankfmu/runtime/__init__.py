"""The code that runs inside the FMUs, bundled whole in every FMU with its model's folder: the
model contract (model.py: PhysicsModel, variables, effects, errors), the integrator
(dopri.py: Dormand-Prince 5(4) on floats; closed_form.py; roots.py) and the one pythonfmu
adapter (slave.py). It imports nothing else of crankfmu and no scipy on its default path."""

"""`--set` values: every parameter of every catalog FMU set to 0, -1, nan, inf, 1e300 and a
string, each on a one-component scene of that FMU (0.01 s, its outputs recorded)."""
from __future__ import annotations

VALUES = ("0", "-1", "nan", "inf", "1e300", "abc")


def single_scene(model: str, outputs: list[str], stop: float = 0.01) -> bytes:
    record = ", ".join(f'"c.{o}"' for o in outputs)
    return (f'[scene]\nname = "single_{model}"\nstop_time = {stop}\n[master]\nstep = 1e-3\n'
            f'[components.c]\nfmu = "{model}"\n[record]\nvariables = [{record}]\n').encode()


def override_cases(fmu_dir, values=VALUES, models=None) -> list[dict]:
    from fmpy import read_model_description

    from crankfmu.models.catalog import FMU_MODELS
    cases = []
    for model in models or FMU_MODELS:
        md = read_model_description(str(fmu_dir / f"{model}.fmu"))
        params = [v.name for v in md.modelVariables if v.causality == "parameter"]
        outputs = [v.name for v in md.modelVariables if v.causality == "output"]
        scene = single_scene(model, outputs)
        for p in params:
            for value in values:
                cases.append({"id": f"set-{model}-{p}-{value}", "family": "set",
                              "kind": f"{model}.{p}={value}", "files": {"scene.toml": scene},
                              "scene": "scene.toml", "args": ["--set", f"c.{p}={value}"],
                              "evil": []})
    return cases

"""caps from Python: the app layer's requests and results (docs/python.md).

Every verb of the ``caps`` program is one request with the same keys as its JSON
(``caps <verb> --json``, the planner's HTTP API): ``caps.run(verb, request)`` takes the request
as a dict and returns the result as a dict. The functions below are keyword spellings of the
common verbs; ``load_model`` and ``read_result`` hand maps and result fields to numpy.

Units are those of the command line: millimetres, degrees, newtons, MPa; positions LPS mm.

    import caps
    caps.phantom("ct.nii.gz", voxels="96,96,90", spacing="2.5,2.5,2.5")
    caps.model_from_volume("ct.nii.gz", "model", n_theta=128, n_z=64)
    caps.plan_new("z-plasty", model="model", at="0,60", output="z.json",
                  parameters={"length": 12, "angle": 60})
    r = caps.simulate(model="model", plan="z.json", output="sim", mesh_size=2.5)
    r["closing_force_n"]
"""

import json as _json
import os as _os

from . import _caps

__all__ = [
    "Error", "InvalidInput", "InvalidParameter", "IoError", "SolverError", "Cancelled",
    "CapsWarning", "run", "defaults", "verbs", "phantom", "model_from_volume", "model_from_scan",
    "model_info", "plan_new", "plan_check", "plan_templates", "plan_suggest", "plan_skin_lines", "mesh", "simulate", "render",
    "load_model", "read_result", "model_landmarks", "model_site", "model_chart", "verb_help",
    "compare", "compare_models", "model_sensitivity",
]


class Error(Exception):
    """A caps error (caps::Error); the message is the command line's."""


class InvalidInput(Error, ValueError):
    """The input is readable but not acceptable (caps::InvalidInput; the CLI's exit code 2)."""


class InvalidParameter(InvalidInput):
    """Invalid named parameters (caps::InvalidParameter); names are spelled as JSON keys."""


class IoError(Error, OSError):
    """A file could not be read or written (caps::IoError; the CLI's exit code 2)."""


class SolverError(Error, RuntimeError):
    """A numerical solve failed (caps::SolverError). Attributes element, gauss_point and
    iteration say where (-1 where not known)."""


class Cancelled(Error):
    """The run was cancelled (a progress callback raised)."""


class CapsWarning(UserWarning):
    """A warning of a caps run (also listed in the result's "warnings")."""


_caps._set_exceptions({
    "Error": Error, "InvalidInput": InvalidInput, "InvalidParameter": InvalidParameter,
    "IoError": IoError, "SolverError": SolverError, "Cancelled": Cancelled,
})


def _plain(value):
    """Paths as strings, for json.dumps."""
    if isinstance(value, _os.PathLike):
        return _os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not a request value (str, number, bool, dict)")


def run(verb, request=None, *, progress=None, **fields):
    """Runs one verb on its request and returns its result.

    verb: "phantom", "model_from_volume", "plan_new", "simulate", ... (see verbs(); the command
        line's spelling "model from-volume" is accepted too).
    request: a dict of the request's fields by JSON key (defaults(verb) lists them); keyword
        arguments are added to it. Paths may be str or os.PathLike.
    progress: optional callable(step: str, fraction: float in 0..1); if it raises, the run stops
        and that exception is raised.
    Returns the result as a dict (what `caps <verb> --json` prints). Warnings are also issued
    as CapsWarning. Raises InvalidInput/InvalidParameter (ValueError), IoError (OSError),
    SolverError (RuntimeError) or Error with the command line's message.
    """
    body = dict(request or {})
    body.update(fields)
    text = _caps.run_json(verb, _json.dumps(body, default=_plain), f"caps.run({verb!r})",
                          CapsWarning, progress)
    return _json.loads(text)


def defaults(verb):
    """Every field of a verb's request with its default (the library's), as a dict."""
    return _json.loads(_caps.defaults_json(verb))


def verbs():
    """The verb names run() accepts: every verb of the caps program but serve, in its order."""
    return list(_caps.verbs())


def verb_help(verb):
    """A verb's help, as ``caps <verb> --help`` prints it."""
    return _caps.verb_help(verb)


def phantom(output, **fields):
    """Writes the analytic head phantom CT (.nii/.nii.gz); fields: voxels "L,P,S",
    spacing "L,P,S" (mm), no_holder, layered, thin_bone, face (a face of analytic landmarks),
    scale (head size), force. Returns output, dims, spacing_mm."""
    return run("phantom", output=output, **fields)


def model_from_volume(input, output, **fields):
    """Builds a patient model directory from a CT or MR volume (caps model from-volume);
    fields: n_theta, n_z, skin_threshold, bone_threshold, ..., force. Returns model_json etc."""
    return run("model_from_volume", input=input, output=output, **fields)


def model_from_scan(input, output, **fields):
    """Builds a patient model directory from a surface scan (caps model from-scan)."""
    return run("model_from_scan", input=input, output=output, **fields)


def model_info(model):
    """A model directory's model.json and summary (caps model info)."""
    return run("model_info", model=model)


def plan_new(procedure, model, output, *, parameters=None, **fields):
    """Lays a procedure (a template such as "z-plasty", or a procedure .json) on the model
    and writes the plan file. fields: at "THETA,Z" (deg, mm) or at_xyz "X,Y,Z" (LPS mm),
    orientation (deg), force; parameters: the template's, e.g. {"length": 12, "angle": 60}
    (mm, deg; see plan_templates()). Returns the plan and its check."""
    return run("plan_new", procedure=procedure, model=model, output=output,
               parameters=dict(parameters or {}), **fields)


def plan_check(plan, model=None):
    """Checks that a plan can be operated on its model; raises InvalidInput if not."""
    request = {"plan": plan}
    if model is not None:
        request["model"] = model
    return run("plan_check", request)


def plan_templates():
    """The procedure templates and their parameters (name, unit, default, min, max), a list."""
    return run("plan_templates")


def plan_skin_lines(model, **fields):
    """Borges's relaxed skin tension lines traced over the model's face (caps plan skin-lines);
    fields: spacing_mm, half_length_mm. Returns {"count", "lines": [{"zone", "points_lps",
    "theta_z"}], "map", "source", "note"} (count 0 and the reason where the model has no nasion
    or subnasale)."""
    return run("plan_skin_lines", model=model, **fields)


def plan_suggest(model, at=None, diameter=None, output=None, *, progress=None, **fields):
    """For a lesion at ``at`` ("THETA,Z" or "glabella+15,20") of ``diameter`` mm, the library's
    closures laid around it at every orientation, closed and ranked (caps plan suggest); or for a
    lesion drawn as its outline: outline="THETA,Z;THETA,Z;..." instead of the diameter (``at``
    then defaults to the outline's centre), or outline_mm="LEFT,UP;..." in mm about ``at``
    (one lesion's shape for every patient). Fields: margin (mm), procedures
    ("ellipse,rhomboid,bilobed,rotation-flap"), step (deg), objective ("force", "features",
    "scar", "excised"), refine, material, force, ... Returns suggestions.json as a dict: "best",
    "designs" (ranked first, each with its figures, plan and rank or refusal), "lesion"."""
    lesion = {k: v for k, v in (("at", at), ("diameter", diameter)) if v is not None}
    return run("plan_suggest", model=model, output=output, progress=progress, **lesion, **fields)


def mesh(model, output, **fields):
    """Meshes a plan's wound on the model (caps mesh); fields: plan or border, mesh_size (mm),
    layers, undermine (mm), rim, base, ..., force."""
    return run("mesh", model=model, output=output, **fields)


def simulate(model, plan, output, *, progress=None, **fields):
    """Meshes the plan on the model and solves the closure (caps simulate); fields: mesh_size
    (mm), undermine (mm), material ("neo-hookean", the default, "linear" or "goh"), steps,
    suture_spacing (mm), render, force, ... Returns closing_force_n (N), max_displacement_mm,
    max_suture_force_n, warnings, ..."""
    return run("simulate", model=model, plan=plan, output=output, progress=progress, **fields)


def compare(model, plan, output, *, progress=None, **fields):
    """Simulates the plan with the measured and with a constant thickness (caps compare);
    fields: thickness (mm, 0: the median measured under the wound), mesh_size, ..., force.
    Returns comparison.json's table and warnings, and output."""
    return run("compare", model=model, plan=plan, output=output, progress=progress, **fields)


def compare_models(model, plan, output, *, progress=None, **fields):
    """Simulates one plan on the CT model and on the scan-built (scan_model, with its
    registration) and fused (fused_model) models (caps compare-models). Returns
    model_comparison.json and output."""
    return run("compare-models", model=model, plan=plan, output=output, progress=progress,
               **fields)


def model_sensitivity(model, output, *, progress=None, **fields):
    """Maps where a constant thickness misleads (caps model sensitivity); fields: procedure,
    length, width (mm), theta "first,last,step" (deg), z "first,last,step" (mm), thickness,
    threads, ..., force. Returns the medians and maxima of the changes and output."""
    return run("model sensitivity", model=model, output=output, progress=progress, **fields)


def render(result, model, output, **fields):
    """Renders a simulation's result directory (caps render)."""
    return run("render", result=result, model=model, output=output, **fields)


def load_model(model):
    """A model directory as a dict: "info" (model.json as a dict), "theta_deg" (n_theta,),
    "z_mm" (n_z,), "axis" (origin_lps, direction, front: LPS), and the maps as numpy arrays of
    shape (n_z, n_theta), row k at z_mm[k], column j at theta_deg[j]: "r_skin", "r_bone",
    "thickness", "thickness_normal" (float32, mm; invalid cells filled), "flags" (uint8,
    0 = valid), "valid", "measured_skin", "measured_bone" (bool); "landmarks": the anatomical
    landmarks by name (docs/landmarks.md: found, theta_deg, z_mm, lps, confidence, thickness_mm,
    note), or None for a model built before landmarks existed (``model_landmarks(model)``)."""
    d = _caps.load_model(_os.fspath(model))
    d["info"] = _json.loads(d.pop("model_json"))
    return d


def model_landmarks(model, write=True):
    """Finds a model's anatomical landmarks (``caps model landmarks``), writes them into its
    model.json unless ``write`` is False, and returns them by name."""
    r = run("model landmarks", {"model": _os.fspath(model), "no_write": not write})
    return r["items"]


def model_site(model, at):
    """The skin point and soft tissue at ``at`` ("THETA,Z" or "glabella+15,20"): theta_deg,
    z_mm, lps, thickness_mm, layers_mm (where measured), flags (``caps model site``)."""
    return run("model site", {"model": _os.fspath(model), "at": at})


def model_chart(model, at, output, **fields):
    """A local chart of a volume-built model (``caps model chart``): the CT measured again on a
    cylinder whose axis faces the skin at ``at`` ("THETA,Z" or a landmark placement), for plans
    where the head's cylinder meets the skin edge-on; the point is theta 0, z 0 of the chart.
    Fields: radius, half_height, normal_radius, n_theta, n_z, series, force."""
    return run("model chart", {"model": _os.fspath(model), "at": at,
                               "output": _os.fspath(output)}, **fields)


def read_result(result):
    """A solve's or simulation's result directory as a dict: "nodes" (#N x 3, LPS mm),
    "displacement" (#N x 3, mm), "max_principal_mpa" (#N, MPa), "result" (result.json as a
    dict: closing force, suture forces, warnings)."""
    path = _os.fspath(result)
    d = _caps.read_result(path)
    with open(_os.path.join(path, "result.json"), encoding="utf-8") as f:
        d["result"] = _json.load(f)
    return d

"""The cohort's plans table, its sweeps expanded: one plan per value.

A value of the plans table is swept by giving several values:

    angle=30:90:15      a range, start:stop:step, stop included: 30, 45, 60, 75, 90
    angle=30,45,60      a list

Sweeps are taken by the template parameters (`parameters`, `k=v;k=v`, options of `caps plan
new`), the options of `caps simulate` (`simulate`, `k=v;k=v`: undermine=0,5,10;prestretch=1.1)
and the `orientation` and `mesh_size` columns. Each value becomes a plan of its own, whose id is
the row's id, `_`, the name and the value: `z` with `angle=30:90:15` gives z_angle30 ..
z_angle90. Several swept values of one row give every combination, in the order parameters,
orientation, mesh_size, simulate (z_angle45_undermine5, ...). The expanded rows keep every column
of the table, with `parameters`, `orientation`, `mesh_size` and `simulate` holding the plan's own
values, `sweep_of` the row it came from and `swept` the names of the row's swept values.

The simulate options are checked against `caps simulate --help` of the caps program the workflow
runs (simulate_options()): the program's own list, not one kept here.
"""

import math
import re
import subprocess

# A range gives at most this many values: a typo such as 0:90:0.01 should not start 9000 jobs.
MAX_SWEEP_VALUES = 100


def _number(text, where):
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{where}: '{text}' is not a number; a sweep is start:stop:step "
                         "(e.g. 30:90:15) or a list (e.g. 30,45,60)") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: '{text}' is not a finite number")
    return value


def _format(value):
    """30.0 -> '30', 2.5 -> '2.5', 0.1 + 0.2 -> '0.3' (12 significant digits)."""
    text = f"{value:.12g}"
    return "0" if text == "-0" else text


# A listed value of a text option (material=linear,neo-hookean): a word, as it names a file.
WORD = re.compile(r"[A-Za-z0-9][A-Za-z0-9.+-]*")


def sweep_values(text, where="sweep", words=False):
    """The values of one parameter: 'a:b:s' (a, a+s, .. up to b, b included), 'a,b,c', or 'a'
    (no sweep), as strings ('30', '2.5'). A list's values are numbers, or with `words` words
    (linear,neo-hookean). Raises ValueError naming `where` and what to write."""
    text = text.strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise ValueError(f"{where}: '{text}' is not start:stop:step (e.g. 30:90:15)")
        start, stop, step = (_number(p.strip(), where) for p in parts)
        if not step > 0 or stop < start:
            raise ValueError(f"{where}: '{text}' needs start <= stop and a step > 0 "
                             "(e.g. 30:90:15 for 30, 45, .., 90)")
        # Values as start + i step, not summed, so 0.1 steps do not drift; stop is included
        # when it is on the grid within a millionth of a step.
        count = math.floor((stop - start) / step + 1e-6) + 1
        if count > MAX_SWEEP_VALUES:
            raise ValueError(f"{where}: '{text}' gives {count} values, more than "
                             f"{MAX_SWEEP_VALUES}; use a larger step")
        return [_format(start + i * step) for i in range(count)]
    if "," in text:
        values = [v.strip() for v in text.split(",")]
        if any(not v for v in values):
            raise ValueError(f"{where}: '{text}' has an empty value; write 30,45,60")
        if len(set(values)) != len(values):
            raise ValueError(f"{where}: '{text}' repeats a value")
        for v in values:  # a value is part of a file name
            if not words:
                _number(v, where)
            elif not WORD.fullmatch(v):
                raise ValueError(f"{where}: '{v}' is not a word (letters, digits, '.', '+', '-'); "
                                 "a swept value is part of the plan's id and file names")
        return values
    return [text]


def parse_parameters(text, where, example="length=12"):
    """'length=12;advance=3' -> [('length', '12'), ('advance', '3')] (values not expanded)."""
    pairs = []
    for item in (p.strip() for p in (text or "").split(";")):
        if not item:
            continue
        if "=" not in item:
            raise ValueError(f"{where}: '{item}' is not name=value (e.g. {example})")
        key, value = (s.strip() for s in item.split("=", 1))
        if not key or not value:
            raise ValueError(f"{where}: '{item}' is not name=value (e.g. {example})")
        if any(k == key for k, _ in pairs):
            raise ValueError(f"{where}: '{key}' is given twice")
        pairs.append((key, value))
    return pairs


# Options of caps simulate that the workflow sets itself: the mesh size is a column of its own.
WORKFLOW_SETS = {"model": "the workflow", "plan": "the workflow", "output": "the workflow",
                 "mesh_size": "the mesh_size column", "json": "the workflow",
                 "quiet": "the workflow", "force": "the workflow", "help": "no plan"}

# One option line of CLI11's help: "  --undermine FLOAT=10  ..." or "  -o,--output TEXT REQUIRED".
_HELP_OPTION = re.compile(r"^  (?:-\w,)?--([a-z0-9-]+)(?: (TEXT|FLOAT|INT)(?:=(\S+))?)?(?: |$)")


def parse_simulate_help(text):
    """`caps simulate --help` -> {key: (type, default)} by JSON key (undermine, suture_spacing):
    type TEXT, FLOAT or INT, or None for a flag; default the help's ('' where it has none)."""
    options = {}
    for line in text.splitlines():
        m = _HELP_OPTION.match(line)
        if m:
            options[m.group(1).replace("-", "_")] = (m.group(2), m.group(3) or "")
    return options


def simulate_options(caps):
    """The options of `caps simulate` of the program `caps` (parse_simulate_help). Raises
    ValueError saying so when the program cannot be run."""
    try:
        run = subprocess.run([caps, "simulate", "--help"], capture_output=True, text=True,
                             timeout=60)
    except OSError as e:
        raise ValueError(f"the plans table sets options of caps simulate, which are checked "
                         f"against `{caps} simulate --help`, and {caps} cannot be run ({e}); "
                         "give the caps program: --config caps=PATH") from None
    options = parse_simulate_help(run.stdout)
    if run.returncode != 0 or "undermine" not in options:
        raise ValueError(f"`{caps} simulate --help` did not list caps simulate's options "
                         f"(exit {run.returncode}): {(run.stdout + run.stderr).strip()[-300:]}")
    return options


def _simulate_key(key, options, where):
    """The table's name of a simulate option (undermine, suture-spacing) -> its JSON key."""
    name = key.replace("-", "_")
    if name not in options:
        known = ", ".join(k for k, (kind, _) in options.items()
                          if kind and k not in WORKFLOW_SETS)
        raise ValueError(f"{where}: caps simulate has no option --{key.replace('_', '-')} "
                         f"(its options with a value: {known})")
    kind = options[name][0]
    if name in WORKFLOW_SETS:
        raise ValueError(f"{where}: --{key.replace('_', '-')} is set by {WORKFLOW_SETS[name]}, "
                         "not in the simulate column")
    if kind is None:
        raise ValueError(f"{where}: --{key.replace('_', '-')} is a flag; the simulate column "
                         "takes options with a value (name=value)")
    return name, kind


def _check_kind(values, kind, where):
    for v in values:
        if kind in ("FLOAT", "INT"):
            number = _number(v, where)
            if kind == "INT" and number != int(number):
                raise ValueError(f"{where}: '{v}' is not a whole number")
        elif not WORD.fullmatch(v):  # on the command line unquoted
            raise ValueError(f"{where}: '{v}' is not a word (letters, digits, '.', '+', '-')")


def expand_plans(rows, options=None):
    """{plan id: row} of the plans table -> {plan id: row}, each sweep expanded into one row per
    value (in the table's order, the first swept value varying slowest). `options` are caps
    simulate's (simulate_options()), needed when a row has simulate options. Raises ValueError
    for a malformed sweep or option, naming the plan and the option, and for an expanded id that
    another row already has."""
    out = {}
    for plan, row in rows.items():
        where = f"plans table, plan '{plan}'"
        axes = []  # (column, name, values)
        for k, v in parse_parameters(row.get("parameters", ""), where):
            axes.append(("parameters", k, sweep_values(v, f"{where}, parameter '{k}'")))
        for column in ("orientation", "mesh_size"):
            text = (row.get(column) or "").strip()
            if text:
                axes.append((column, column, sweep_values(text, f"{where}, {column}")))
        for k, v in parse_parameters(row.get("simulate", ""), f"{where}, simulate",
                                     "undermine=5"):
            at = f"{where}, simulate option '{k}'"
            if options is None:
                raise ValueError(f"{at}: no list of caps simulate's options to check it against")
            name, kind = _simulate_key(k, options, at)
            values = sweep_values(v, at, words=kind == "TEXT")
            _check_kind(values, kind, at)
            axes.append(("simulate", name, values))
        swept = [key for _, key, values in axes if len(values) > 1]
        combos = [([], plan)]
        for column, key, values in axes:
            combos = [(chosen + [(column, key, v)], f"{name}_{key}{v}" if key in swept else name)
                      for chosen, name in combos for v in values]
        for chosen, name in combos:
            if name in out:
                raise ValueError(f"{where}: the plan id '{name}' is used twice; rename a row")
            expanded = dict(row)
            for column in ("parameters", "simulate"):
                expanded[column] = ";".join(f"{k}={v}" for c, k, v in chosen if c == column)
            for column in ("orientation", "mesh_size"):
                expanded[column] = next((v for c, _, v in chosen if c == column), "")
            expanded["sweep_of"] = plan
            expanded["swept"] = swept
            out[name] = expanded
    return out


# Paths that do not exist: caps checks its options before it reads the model and the plan.
_NO_FILE = "/nonexistent/caps-cohort-check"


def _refusals(caps, calls):
    """Runs `caps simulate` with each call's options ([(key, value)]) and paths that do not
    exist, side by side: [(call, caps's message)] for the calls it refuses before the files."""
    runs = [(call, subprocess.Popen(
                [caps, "simulate", "--model", _NO_FILE, "--plan", _NO_FILE, "-o", _NO_FILE,
                 *(a for k, v in call for a in (f"--{k.replace('_', '-')}", v)), "-q"],
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True))
            for call in calls]
    out = [(call, run.communicate(timeout=60)[1].strip()) for call, run in runs]
    return [(call, message) for call, message in out if _NO_FILE not in message]


def check_simulate_values(caps, plans):
    """Asks the caps program about the simulate options' values of the expanded plans (e.g.
    material=foo, rim=clamp, steps=0) before any job: `caps simulate` with the options and paths
    that do not exist refuses a bad value with its own message before it looks for the files.
    One call per value of the option with the most values (each call gives every option one of
    its values); a refused call is asked again option by option, to name the option, and where
    no option alone is refused, with each plan's own options (a mix of two rows' values that
    caps refuses is no plan's). Raises
    ValueError naming the plan table's row, the option and caps's message. (Values that caps can
    only judge on the model or the mesh are refused by the simulation's job.)"""
    values, rows = {}, {}  # key -> [values]; (key, value) -> the first row that sets it
    for row in plans.values():
        for key, value in parse_parameters(row.get("simulate", ""), "plans table"):
            if (key, value) not in rows:
                values.setdefault(key, []).append(value)
                rows[key, value] = row.get("sweep_of", "?")
    rounds = max(map(len, values.values()), default=0)
    calls = [[(k, vs[min(i, len(vs) - 1)]) for k, vs in values.items()] for i in range(rounds)]
    refused = {pair for call, _ in _refusals(caps, calls) for pair in call}
    errors = [f"plans table, plan '{rows[key, value]}', simulate option '{key}': caps simulate "
              f"refuses {key}={value}: {message}"
              for [(key, value)], message in _refusals(caps, [[p] for p in sorted(refused)])]
    if refused and not errors:  # refused together only: ask each plan's own options
        sets = {}  # the plans' distinct option sets that hold a refused pair -> the first plan
        for plan, row in plans.items():
            pairs = tuple(parse_parameters(row.get("simulate", ""), "plans table"))
            if refused & set(pairs):
                sets.setdefault(pairs, plan)
        errors = [f"plans table, plan '{sets[tuple(call)]}': caps simulate refuses "
                  f"{';'.join(f'{k}={v}' for k, v in call)}: {message}"
                  for call, message in _refusals(caps, [list(s) for s in sets])]
    if errors:
        raise ValueError("\n".join(errors))


def simulate_settings(plans, options):
    """The caps simulate options the plans set, as {JSON key: default of caps}, in the order
    first met: the results table's columns (a plan that does not set one has the default)."""
    keys = {}
    for row in plans.values():
        for k, _ in parse_parameters(row.get("simulate", ""), "plans table"):
            keys.setdefault(k, options[k][1])
    return keys


def simulate_arguments(row):
    """A plan's simulate options (numbers and words, expand_plans()) as options of `caps
    simulate`: 'undermine=5;material=neo-hookean' -> '--undermine 5 --material neo-hookean'."""
    return plan_options({"parameters": row.get("simulate", "")})


def plan_options(row):
    """A plan's parameters as options of `caps plan new`: 'length=12;advance=3' ->
    '--length 12 --advance 3'."""
    pairs = parse_parameters(row.get("parameters", ""), "plans table")
    return " ".join(f"--{k.replace('_', '-')} {v}" for k, v in pairs)


def lesion_shape(lesion, where="lesions table"):
    """A lesion's size as arguments of `caps plan suggest`: its outline in mm about its centre
    (column outline_mm, LEFT,UP;LEFT,UP;... to the patient's left and up along the skin: one
    lesion's shape on every patient) or its largest diameter in mm (column diameter); exactly
    one of the two."""
    outline = (lesion.get("outline_mm") or "").strip()
    diameter = (lesion.get("diameter") or "").strip()
    name = lesion.get("lesion", "?")
    if bool(outline) == bool(diameter):
        raise ValueError(f"{where}, lesion '{name}': give its diameter (mm) or its outline_mm "
                         f"(LEFT,UP;LEFT,UP;... mm about its centre), one of the two")
    if outline:
        if not re.fullmatch(r"[0-9eE.,;+\- ]+", outline):
            raise ValueError(f"{where}, lesion '{name}', outline_mm: '{outline}' is not "
                             f"LEFT,UP;LEFT,UP;... in mm (numbers, commas and semicolons)")
        return ["--outline-mm", outline]
    _number(diameter, f"{where}, lesion '{name}', diameter")
    return ["--diameter", diameter]


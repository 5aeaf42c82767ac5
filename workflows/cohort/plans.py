"""The cohort's plans table, its sweeps expanded: one plan per value.

A parameter of the plans table's `parameters` column (`k=v;k=v`, options of `caps plan new`) is
swept by giving several values:

    angle=30:90:15      a range, start:stop:step, stop included: 30, 45, 60, 75, 90
    angle=30,45,60      a list

Each value becomes a plan of its own, whose id is the row's id, `_`, the parameter's name and the
value: `z` with `angle=30:90:15` gives z_angle30 .. z_angle90. Two swept parameters of one row give
every combination (z_angle45_length10, ...). The expanded rows keep every column of the table, with
`parameters` holding the plan's own values and `sweep_of` the row it came from.
"""

import math

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


def sweep_values(text, where="sweep"):
    """The values of one parameter: 'a:b:s' (a, a+s, .. up to b, b included), 'a,b,c', or 'a'
    (no sweep), as strings ('30', '2.5'). Raises ValueError naming `where` and what to write."""
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
        for v in values:  # every template parameter is a number; a value is part of a file name
            _number(v, where)
        return values
    return [text]


def parse_parameters(text, where):
    """'length=12;advance=3' -> [('length', '12'), ('advance', '3')] (values not expanded)."""
    pairs = []
    for item in (p.strip() for p in (text or "").split(";")):
        if not item:
            continue
        if "=" not in item:
            raise ValueError(f"{where}: '{item}' is not name=value (e.g. length=12)")
        key, value = (s.strip() for s in item.split("=", 1))
        if not key or not value:
            raise ValueError(f"{where}: '{item}' is not name=value (e.g. length=12)")
        pairs.append((key, value))
    return pairs


def expand_plans(rows):
    """{plan id: row} of the plans table -> {plan id: row}, each sweep expanded into one row per
    value (in the table's order, the first swept parameter varying slowest). Raises ValueError
    for a malformed sweep or an expanded id that another row already has."""
    out = {}
    for plan, row in rows.items():
        where = f"plans table, plan '{plan}'"
        pairs = parse_parameters(row.get("parameters", ""), where)
        choices = [(k, sweep_values(v, f"{where}, parameter '{k}'")) for k, v in pairs]
        combos = [([], plan)]
        for key, values in choices:
            swept = len(values) > 1
            combos = [(chosen + [(key, v)], f"{name}_{key}{v}" if swept else name)
                      for chosen, name in combos for v in values]
        for chosen, name in combos:
            if name in out:
                raise ValueError(f"{where}: the plan id '{name}' is used twice; rename a row")
            expanded = dict(row)
            expanded["parameters"] = ";".join(f"{k}={v}" for k, v in chosen)
            expanded["sweep_of"] = plan
            out[name] = expanded
    return out


def plan_options(row):
    """A plan's parameters as options of `caps plan new`: 'length=12;advance=3' ->
    '--length 12 --advance 3'."""
    pairs = parse_parameters(row.get("parameters", ""), "plans table")
    return " ".join(f"--{k.replace('_', '-')} {v}" for k, v in pairs)

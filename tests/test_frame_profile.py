"""The profile's bookkeeping: statements of the generated C++ mapped onto Python lines."""

from benchmarks.frame_profile import function_name, generated_statements, statement_at

CPP = """\
// /src/kernels/a.py:10
static void a_funcs__locals__f_1(
    float var_x)
{
    // y = x + 1.0                                                       <L 12>
    var_0 = wp::add(var_x, var_1);
    var_2 = wp::mul(var_0, var_0);
    // return y * y                                                      <L 13>
    return var_2;
}

template <bool wp_linear_contiguous>
static void k__locals__run_cpu_kernel_forward(
    wp::launch_bounds_t<1> dim)
{
    // i = wp.tid()                                                      <L 40>
    var_i = builtin_tid1d();
}
"""


def test_each_generated_line_maps_to_the_statement_above_it():
    statements = generated_statements(CPP, "/src/kernels/k.py")
    assert [(n, s.line, s.text, s.function) for n, s in statements] == [
        (5, 12, "y = x + 1.0", "/src/kernels/a.py:10"),
        (8, 13, "return y * y", "/src/kernels/a.py:10"),
        (16, 40, "i = wp.tid()", "/src/kernels/k.py:kernel"),
    ]
    assert statement_at(statements, 1) is None  # above every statement
    assert statement_at(statements, 5).line == 12
    assert statement_at(statements, 7).line == 12  # the statement's generated code
    assert statement_at(statements, 9).line == 13
    assert statement_at(statements, 17).file == "/src/kernels/k.py"


def test_function_names_are_read_from_the_source(tmp_path):
    source = tmp_path / "m.py"
    source.write_text("x = 1\n\n    @wp.func\n    def grid_fits(q):\n        return q\n")
    assert function_name(f"{source}:3") == f"grid_fits ({source}:3)"
    assert function_name(f"{source}:kernel") == f"kernel ({source})"
    assert function_name(f"{tmp_path}/missing.py:3") == f"{tmp_path}/missing.py:3"


def _run(prec, motion, speed, ns, functions):
    """A profiled run as ``profile_case`` returns it: ``functions`` maps a name to samples."""
    return {"precision": prec, "motion": motion, "speed": speed, "ns_per_sphere_frame": ns,
            "in_kernel": sum(functions.values()),
            "functions": [{"function": f, "samples": n} for f, n in functions.items()]}


def test_function_nanoseconds_split_the_runs_cost_by_share():
    from benchmarks.frame_profile import function_ns

    run = _run("float32", "linear", 5.0, 40.0, {"fit": 30, "loop": 10})
    assert function_ns(run) == {"fit": 30.0, "loop": 10.0}


def test_compare_lists_the_largest_increase_first_and_the_whole_difference():
    from benchmarks.frame_profile import compare

    slow = _run("float32", "linear", 5.0, 20.0, {"fit": 10, "loop": 10})  # 10 + 10 ns
    fast = _run("float32", "linear", 60.0, 80.0, {"fit": 1, "loop": 5, "sweep": 2})  # 10 50 20
    rows = compare(slow, fast, top=2)
    assert [r["function"] for r in rows] == ["loop", "sweep", "(every function)"]
    assert rows[0]["base"] == 10.0 and rows[0]["other"] == 50.0 and rows[0]["difference"] == 40.0
    assert rows[1]["base"] == 0.0 and rows[1]["difference"] == 20.0
    whole = rows[-1]
    assert whole["base"] == 20.0 and whole["other"] == 80.0 and whole["difference"] == 60.0
    # the whole difference is the sum over every function, those left out of the top included
    assert sum(r["difference"] for r in compare(slow, fast, top=10)[:-1]) == 60.0


def test_comparisons_pair_speeds_within_a_case_and_cases_at_a_speed():
    from benchmarks.frame_profile import comparisons, run_title

    runs = [_run(p, m, s, 10.0, {"f": 1}) for p, m in (("float32", "linear"),
                                                       ("float32", "ballistic"))
            for s in (5.0, 60.0)]
    runs.append({"precision": "float64", "motion": "linear", "speed": 5.0, "error": "no perf"})
    pairs = [(run_title(a), run_title(b)) for a, b in comparisons(runs)]
    assert pairs == [
        ("float32 linear 5 m/s", "float32 linear 60 m/s"),
        ("float32 ballistic 5 m/s", "float32 ballistic 60 m/s"),
        ("float32 linear 5 m/s", "float32 ballistic 5 m/s"),
        ("float32 linear 60 m/s", "float32 ballistic 60 m/s"),
    ]
    assert comparisons(runs[:1]) == []  # one run: nothing to compare

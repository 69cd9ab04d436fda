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

"""The drilling tool model (issue 38, deliverable 1): the bone file and its refusals, the cutting law
against its closed form, the engagement ramp's C1 joins by finite differences, the work of a hole
against an independent quadrature, the derivatives against finite differences, and the C header
against the Python, equal at every sample."""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from vgtarm.drilling import (
    HEADER,
    bone_from_dict,
    drilling_forces,
    drilling_forces_at,
    engagement,
    engagement_slope,
    feed_law,
    layer_index,
    layer_weights,
    load_bone,
)
from vgtarm.errors import ConfigError, InputError

BONES = Path(__file__).resolve().parents[1] / "examples" / "bones"
#: 1500 rpm (rad/s), the bones' reference speed.
RPM_1500 = 50.0 * math.pi
RPM = 2.0 * math.pi / 60.0


@pytest.fixture(scope="module")
def femur():
    return load_bone(BONES / "femur_diaphysis.toml")


@pytest.fixture(scope="module")
def tibia():
    return load_bone(BONES / "tibia_metaphysis.toml")


def _thrust(bone, z, v=1e-3, w=RPM_1500):
    return float(drilling_forces(bone, z, v, w).thrust)


# -- the law ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("feed", [0.5e-3, 1e-3, 2e-3, 1e-4])
@pytest.mark.parametrize("rpm", [1000.0, 1500.0, 3000.0])
@pytest.mark.parametrize("layer", [0, 1, 2])
def test_inside_a_layer_the_thrust_is_the_power_law_k_f_a_n_b(femur, feed, rpm, layer):
    """Away from the interfaces by more than the point, a layer alone cuts: thrust = K f^a N^b with
    K in SI units (N / ((m/s)^a (rad/s)^b)), written out here from the material's constants."""
    m = femur.material(femur.layers[layer].material)
    edges = femur.boundaries
    z = 0.5 * (edges[layer] + femur.point_length + edges[layer + 1])  # the point wholly inside
    assert edges[layer] + femur.point_length < z < edges[layer + 1]
    w = rpm * RPM
    k_si = m.thrust / (femur.reference_feed**m.thrust_feed_exponent * femur.reference_speed**m.thrust_speed_exponent)
    expected = k_si * feed**m.thrust_feed_exponent * w**m.thrust_speed_exponent
    t_si = m.torque / (femur.reference_feed**m.torque_feed_exponent * femur.reference_speed**m.torque_speed_exponent)
    got = drilling_forces(femur, z, feed, w)
    assert float(got.thrust) == pytest.approx(expected, rel=1e-13)
    assert float(got.torque) == pytest.approx(
        t_si * feed**m.torque_feed_exponent * w**m.torque_speed_exponent, rel=1e-13
    )
    assert float(got.thrust_depth_slope) == 0.0  # no interface under the point


def test_the_nominal_thrusts_are_those_of_the_file_and_in_the_published_range(femur):
    """20 N of cortical and 5 N of cancellous bone at 1 mm/s and 1500 rpm (the file's constants);
    across 0.5-2 mm/s and 1000-3000 rpm the cortical thrust stays within 10-40 N."""
    mid = [0.5 * (a + femur.point_length + b) for a, b in zip(femur.boundaries[:-1], femur.boundaries[1:], strict=True)]
    np.testing.assert_allclose(drilling_forces(femur, mid, 1e-3, RPM_1500).thrust, [20.0, 5.0, 20.0], rtol=1e-15)
    corners = [_thrust(femur, mid[0], v, rpm * RPM) for v in (0.5e-3, 2e-3) for rpm in (1000.0, 3000.0)]
    assert 10.0 < min(corners) and max(corners) < 40.0, corners


def test_a_denser_layer_cuts_harder_as_its_density_squared(tibia):
    """The tibia's core is 400 kg/m^3 against its material's 300: thrust x (4/3)^2."""
    assert tibia.coefficients[1, 0] == pytest.approx(5.0 * (400.0 / 300.0) ** 2, rel=1e-15)


def test_the_feed_law_meets_the_power_law_at_the_floor_with_its_slope_and_is_zero_below_zero():
    a, ref, floor = 0.6, 1e-3, 5e-5
    g, dg = feed_law(np.array([floor]), a, ref, floor)
    g_below, dg_below = feed_law(np.array([floor * (1 - 1e-12)]), a, ref, floor)
    assert g_below[0] == pytest.approx(g[0], rel=1e-11) and dg_below[0] == pytest.approx(dg[0], rel=1e-10)
    assert dg[0] == pytest.approx(a * (floor / ref) ** a / floor, rel=1e-14)
    g0, dg0 = feed_law(np.array([1e-300, 0.0, -1e-3]), a, ref, floor)
    assert dg0[0] == pytest.approx((floor / ref) ** a * (2 - a) / floor, rel=1e-12)  # finite damping at 0+
    assert g0[1] == g0[2] == dg0[1] == dg0[2] == 0.0


def test_the_derivatives_are_those_of_the_thrust_by_central_differences(femur, tibia):
    """Over the whole hole (the ramps included: the thrust is C1 in depth) and over feeds below,
    around and above the floor (C1 in feed for feed > 0)."""
    for bone in (femur, tibia):
        z = np.linspace(-0.5e-3, bone.breakthrough_depth + 0.5e-3, 397)
        h = 1e-9
        up, down = drilling_forces(bone, z + h, 1e-3, RPM_1500), drilling_forces(bone, z - h, 1e-3, RPM_1500)
        slope = drilling_forces(bone, z, 1e-3, RPM_1500).thrust_depth_slope
        np.testing.assert_allclose(slope, (up.thrust - down.thrust) / (2 * h), rtol=1e-5, atol=1e-6 * abs(slope).max())
    z = 0.5 * (femur.point_length + femur.boundaries[1]) - 0.3e-3  # inside the first cortex
    v = np.array([1e-6, 2e-5, 4.9e-5, 5e-5, 5.1e-5, 1e-4, 1e-3, 3e-3])
    h = 1e-11
    fd = (drilling_forces(femur, z, v + h, 2000 * RPM).thrust - drilling_forces(femur, z, v - h, 2000 * RPM).thrust) / (
        2 * h
    )
    np.testing.assert_allclose(drilling_forces(femur, z, v, 2000 * RPM).thrust_feed_slope, fd, rtol=1e-5)


# -- the engagement ramp ------------------------------------------------------------------------------


def test_the_ramp_is_c1_at_both_ends_by_one_sided_differences():
    """E(0) = 0, E(L) = 1, E(L/2) = 1/2, and at each end the slopes from the left and from the right
    (one-sided differences) are both zero to O(h); the analytic slope agrees inside."""
    length, h = 1.6e-3, 1e-9
    assert engagement(0.0, length) == 0.0 and engagement(length, length) == 1.0
    assert engagement(0.5 * length, length) == 0.5
    for end in (0.0, length):
        left = (engagement(end, length) - engagement(end - h, length)) / h
        right = (engagement(end + h, length) - engagement(end, length)) / h
        assert abs(left) < 1e-5 / length and abs(right) < 1e-5 / length, (end, left, right)
        assert engagement_slope(end, length) == 0.0
    u = np.linspace(0.01, 0.99, 50) * length
    fd = (engagement(u + h, length) - engagement(u - h, length)) / (2 * h)
    np.testing.assert_allclose(engagement_slope(u, length), fd, rtol=1e-6)


def _ramp_ends(bone):
    """Every depth where a ramp starts or ends: the interfaces and one chisel length and one point
    length past each."""
    return sorted({*bone.boundaries, *(bone.boundaries + bone.chisel_length), *(bone.boundaries + bone.point_length)})


def test_the_thrust_is_c1_across_every_interface_and_the_breakthrough(femur, tibia):
    """At each interface, one chisel length and one point length past it (the ends of every ramp)
    the thrust is continuous and its one-sided slopes agree to O(h)."""
    for bone in (femur, tibia):
        assert bone.chisel_share > 0.0
        h = 1e-4 * bone.chisel_length
        scale = 20.0 / bone.chisel_length  # a slope of the size of the steepest ramp
        for z in _ramp_ends(bone):
            left = (_thrust(bone, z) - _thrust(bone, z - h)) / h
            right = (_thrust(bone, z + h) - _thrust(bone, z)) / h
            assert abs(left - right) < 1e-3 * scale, (bone.name, z, left, right)
            assert abs(_thrust(bone, z + 1e-12) - _thrust(bone, z - 1e-12)) < 1e-6


def test_the_forces_are_zero_before_contact_after_breakthrough_and_when_not_feeding(femur):
    z = np.array([-1.0, -1e-9, 0.0, femur.breakthrough_depth, femur.breakthrough_depth + 1e-9, 1.0])
    out = drilling_forces(femur, z, 1e-3, RPM_1500)
    for values in (out.thrust, out.torque, out.thrust_depth_slope, out.thrust_feed_slope):
        np.testing.assert_array_equal(values, 0.0)
    inside = np.linspace(1e-5, femur.breakthrough_depth - 1e-5, 101)
    assert (drilling_forces(femur, inside, 1e-3, RPM_1500).thrust > 0.0).all()
    for v in (0.0, -1e-12, -2e-3):  # retracting or still: nothing is cut, no rubbing
        out = drilling_forces(femur, inside, v, RPM_1500)
        assert not out.thrust.any() and not out.torque.any() and not out.thrust_feed_slope.any()


def test_the_thrust_grows_with_the_feed_and_falls_with_the_speed(femur):
    z = np.linspace(1e-4, femur.breakthrough_depth - 1e-4, 37)[:, None]
    v = np.geomspace(1e-6, 5e-3, 60)[None, :]
    thrust = drilling_forces(femur, z, v, RPM_1500).thrust
    assert (np.diff(thrust, axis=1) > 0.0).all()
    speeds = np.linspace(500, 5000, 30) * RPM
    assert (np.diff(drilling_forces(femur, z, 1e-3, speeds[None, :]).thrust, axis=1) < 0.0).all()


def test_a_layer_thinner_than_the_point_is_never_fully_engaged(tibia):
    weights, _ = layer_weights(tibia, np.linspace(0.0, tibia.breakthrough_depth, 4001))
    assert weights[:, 0].max() < 1.0 and weights[:, 1].max() == 1.0
    np.testing.assert_allclose(weights.sum(axis=1).max(), 1.0, rtol=0, atol=1e-15)


def test_the_layer_index_says_where_the_tip_is(femur):
    z = [-1e-3, 0.0, 1e-6, 4e-3, 4e-3 + 1e-9, 13.9e-3, 14e-3, 14.1e-3]
    np.testing.assert_array_equal(layer_index(femur, z), [-1, -1, 0, 0, 1, 2, 2, 3])


# -- the work of a hole -------------------------------------------------------------------------------


def test_the_ramp_has_the_mean_of_the_straight_one():
    length = 1.6e-3
    area, _ = quad(lambda u: float(engagement(u, length)), 0.0, length, epsabs=0, epsrel=1e-13)
    assert area == pytest.approx(0.5 * length, rel=1e-12)


@pytest.mark.parametrize("name", ["femur", "tibia"])
@pytest.mark.parametrize("feed", [0.5e-3, 1.7e-3])
def test_the_work_of_a_hole_is_the_sum_of_thrust_times_thickness(name, feed, request):
    """At a constant feed the work of the thrust over the whole travel (quadrature, split at every
    ramp's ends) equals sum_i F_i h_i: each ramp in (the lips' and the chisel's) gives what the
    ramp out takes, whatever its shape and the chisel's share; and each layer's own share
    integrates to F_i h_i."""
    bone = request.getfixturevalue(name)
    speed = 2200 * RPM
    full = np.array([_thrust_of_layer(bone, i, feed, speed) for i in range(len(bone.layers))])
    thickness = np.diff(bone.boundaries)
    breaks = _ramp_ends(bone)
    work = sum(
        quad(lambda z: _thrust(bone, z, feed, speed), a, b, epsabs=0, epsrel=1e-12)[0]
        for a, b in zip(breaks[:-1], breaks[1:], strict=True)
    )
    assert work == pytest.approx(float(full @ thickness), rel=1e-10)
    for i in range(len(bone.layers)):
        share = sum(
            quad(lambda z, i=i: float(layer_weights(bone, z)[0][i]), a, b, epsabs=0, epsrel=1e-12)[0]
            for a, b in zip(breaks[:-1], breaks[1:], strict=True)
        )
        assert share == pytest.approx(thickness[i], rel=1e-10)


def _thrust_of_layer(bone, i, feed, speed):
    """F_i from the material's constants, independently of the weights: K (v/v0)^a (w/w0)^b (rho/rho0)^d."""
    layer = bone.layers[i]
    m = bone.material(layer.material)
    density = (layer.density / m.density) ** m.density_exponent
    return (
        m.thrust
        * density
        * (feed / bone.reference_feed) ** m.thrust_feed_exponent
        * (speed / bone.reference_speed) ** m.thrust_speed_exponent
    )


# -- the file and its refusals ------------------------------------------------------------------------


def test_a_bone_reads_back_from_its_dict(femur, tibia):
    for bone in (femur, tibia):
        assert bone_from_dict(bone.to_dict(), source="again") == bone
        assert not bone.coefficients.flags.writeable and not bone.boundaries.flags.writeable


def _with(data, path, value):
    """``data`` (a bone's dict) with the field at ``path`` (keys and indices) set to ``value``,
    or removed when ``value`` is ``...``."""
    import copy

    out = copy.deepcopy(data)
    node = out
    for key in path[:-1]:
        node = node[key]
    if value is ...:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return out


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (
            ("layers", 1, "thickness"),
            -1e-3,
            r"field 'layers\[1\]\.thickness' = -0\.001: expected a number in \(0, 1\] \(m\)",
        ),
        (
            ("layers", 0, "thickness"),
            0.0,
            r"field 'layers\[0\]\.thickness' = 0\.0: expected a number in \(0, 1\] \(m\)",
        ),
        (("layers", 2, "thickness"), math.nan, r"field 'layers\[2\]\.thickness' = nan: expected"),
        (("layers",), [], r"field 'layers' = \[\]: expected a list of one or more layers"),
        (("layers", 1, "material"), "marrow", r"field 'layers\[1\]\.material' = 'marrow': expected one of"),
        (("layers", 1, "density"), -5.0, r"field 'layers\[1\]\.density' = -5\.0: expected"),
        (("materials", "cortical", "thrust"), math.nan, r"field 'materials\.cortical\.thrust' = nan: expected"),
        (("materials", "cortical", "thrust_feed_exponent"), 2.0, r"'materials\.cortical\.thrust_feed_exponent'"),
        (("materials", "cancellous", "torque"), ..., r"missing key 'materials\.cancellous\.torque'"),
        (("drill", "point_angle"), math.pi, r"field 'drill\.point_angle' = 3\.14159\d*: expected a number in \(0, "),
        (("drill", "diameter"), True, r"field 'drill\.diameter' = True: expected"),
        (
            ("model", "reference_speed"),
            0,
            r"field 'model\.reference_speed' = 0: expected a number in \(0, 100000\] \(rad/s\)",
        ),
        (("model", "feed_floor"), ..., r"missing key 'model\.feed_floor'"),
        (("materials",), {}, r"field 'materials' = \{\}: expected a table of one or more materials"),
        (("colour",), "red", r"unknown key 'colour'"),
        (("name",), "", r"field 'name' = '': expected a text"),
    ],
)
def test_a_bad_bone_is_refused_in_one_line_naming_the_field(femur, path, value, message):
    with pytest.raises(ConfigError, match=message) as caught:
        bone_from_dict(_with(femur.to_dict(), path, value), source="bone.toml")
    assert "\n" not in str(caught.value) and str(caught.value).startswith("bone.toml: ")


def test_a_bone_file_with_a_negative_thickness_is_refused_naming_the_file_and_the_field(tmp_path):
    text = (BONES / "femur_diaphysis.toml").read_text().replace("thickness = 6.0e-3", "thickness = -6.0e-3")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    with pytest.raises(ConfigError, match=r"bad\.toml: field 'layers\[1\]\.thickness' = -0\.006: expected"):
        load_bone(bad)
    bad.write_text("layers = [")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_bone(bad)
    with pytest.raises(ConfigError, match="not found"):
        load_bone(tmp_path / "missing.toml")


def test_the_functions_refuse_a_speed_that_is_not_positive_and_a_nan(femur):
    with pytest.raises(InputError, match=r"spindle_speed\[1\] = 0\.0: expected a finite number > 0 \(rad/s\)"):
        drilling_forces(femur, 1e-3, 1e-3, [100.0, 0.0])
    with pytest.raises(InputError, match=r"depth\[0\] = nan: expected a finite number"):
        drilling_forces(femur, [math.nan], 1e-3, 100.0)
    with pytest.raises(InputError, match="shapes that broadcast"):
        drilling_forces(femur, [1e-3, 2e-3], [1e-3, 1e-3, 1e-3], 100.0)


# -- the C header -------------------------------------------------------------------------------------

_SHIM = r"""
#include "vgt_drill.h"

void drill_many(int m, const double *depth, const double *feed, const double *speed, int n,
                const double *boundaries, const double *coefficients, double point_length,
                double chisel_length, double chisel_share, double feed_ref, double speed_ref,
                double feed_floor, double *out)
{
    for (int k = 0; k < m; ++k)
        vgt_drill_forces(n, boundaries, coefficients, point_length, chisel_length, chisel_share, feed_ref,
                         speed_ref, feed_floor, depth[k], feed[k], speed[k], out + 4 * k);
}
"""


@pytest.fixture(scope="module")
def shim(tmp_path_factory):
    """The header compiled in a tiny library as the model's C is (-O2, no contraction), strict C99."""
    from vgtarm import compiler
    from vgtarm.model.compiling import find_compiler

    cc = find_compiler()
    if cc is None:
        pytest.skip("no C compiler")
    folder = tmp_path_factory.mktemp("drill")
    (folder / "shim.c").write_text(_SHIM)
    library = folder / "shim.so"
    flags = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-fPIC", "-shared", "-ffp-contract=off"]
    compiler.compile_checked(
        [cc, *flags, "-I", str(HEADER.parent), "-o", str(library), str(folder / "shim.c"), "-lm"], what="shim.c"
    )
    lib = ctypes.CDLL(str(library))
    lib.drill_many.restype = None
    return lib


def _c_forces(lib, bone, depth, feed, speed):
    p = ctypes.POINTER(ctypes.c_double)
    z, v, w = (np.ascontiguousarray(x, dtype=np.float64) for x in np.broadcast_arrays(depth, feed, speed))
    edges = np.ascontiguousarray(bone.boundaries)
    table = np.ascontiguousarray(bone.coefficients)
    out = np.empty((z.size, 4))
    d = ctypes.c_double
    lib.drill_many(
        ctypes.c_int(z.size),
        *(a.ctypes.data_as(p) for a in (z, v, w)),
        ctypes.c_int(len(bone.layers)),
        edges.ctypes.data_as(p),
        table.ctypes.data_as(p),
        d(bone.point_length),
        d(bone.chisel_length),
        d(bone.chisel_share),
        d(bone.reference_feed),
        d(bone.reference_speed),
        d(bone.feed_floor),
        out.ctypes.data_as(p),
    )
    return out


@pytest.mark.parametrize("name", ["femur", "tibia"])
def test_the_c_header_gives_the_python_numbers_exactly(shim, name, request):
    """Every sample of a seeded grid of depths (the interfaces and ramp ends included), feeds
    (retracting, below, at and above the floor) and speeds: the C header and the NumPy functions
    give equal thrust, torque and slopes (==, not a tolerance), and so does the scalar function."""
    bone = request.getfixturevalue(name)
    rng = np.random.default_rng(38)
    depth = np.concatenate(
        [
            rng.uniform(-1e-3, bone.breakthrough_depth + 1e-3, 4000),
            bone.boundaries,
            bone.boundaries + bone.point_length,
            np.nextafter(bone.boundaries, 1.0),
        ]
    )
    feed = rng.choice([-1e-3, 0.0, 1e-5, bone.feed_floor, 5e-4, 1e-3, 2e-3], depth.size) * rng.uniform(
        0.5, 1.5, depth.size
    )
    speed = rng.uniform(500, 4000, depth.size) * RPM
    mine = drilling_forces(bone, depth, feed, speed)
    theirs = _c_forces(shim, bone, depth, feed, speed)
    one_by_one = np.array([drilling_forces_at(bone, *x) for x in zip(depth, feed, speed, strict=True)])
    for column, values in enumerate((mine.thrust, mine.torque, mine.thrust_depth_slope, mine.thrust_feed_slope)):
        np.testing.assert_array_equal(theirs[:, column], values)
        np.testing.assert_array_equal(one_by_one[:, column], values)
    assert (mine.thrust > 0).sum() > 1000  # most samples cut


def test_the_header_is_c99_without_heap_or_state():
    text = HEADER.read_text()
    for banned in ("malloc", "calloc", "free(", "static double", "static int", "printf"):
        assert banned not in text, banned


# -- the chisel edge ----------------------------------------------------------------------------------


def _with_drill(bone, **drill):
    data = bone.to_dict()
    data["drill"].update(drill)
    return bone_from_dict(data, source="drill changed")


def _smoothstep(u, length):
    """The cubic smoothstep written out again: 0 before 0, 1 after ``length``."""
    s = min(max(u / length, 0.0), 1.0)
    return 3.0 * s**2 - 2.0 * s**3


def test_the_example_drill_has_its_chisel_of_the_file(femur):
    """0.5 of the thrust on a chisel of web 0.32 mm: axial length 0.16 mm at a 90 degree point."""
    assert femur.chisel_share == 0.5
    assert femur.chisel_length == pytest.approx(0.16e-3, rel=1e-12)
    assert femur.point_length == pytest.approx(1.6e-3, rel=1e-12)


def test_the_thrust_at_the_far_surface_falls_with_the_chisel_in_closed_form(femur):
    """Past the far surface by u the last layer's thrust is F (1 - c E_l(u) - (1 - c) E_L(u)) (the
    other layers long left): the chisel's share leaves over its 0.16 mm, the lips' over 1.6 mm."""
    far = femur.thickness
    force = 20.0
    c, small, big = femur.chisel_share, femur.chisel_length, femur.point_length
    for u in (0.0, 0.02e-3, 0.08e-3, 0.16e-3, 0.5e-3, 1.2e-3):
        expected = force * (1.0 - c * _smoothstep(u, small) - (1.0 - c) * _smoothstep(u, big))
        assert _thrust(femur, far + u) == pytest.approx(expected, rel=1e-12, abs=1e-12)
    # one chisel length past the surface the thrust has lost the chisel's share and a little more
    assert _thrust(femur, far + small) / force == pytest.approx(0.5 - 0.5 * _smoothstep(small, big), rel=1e-12)


def test_without_a_chisel_share_the_model_is_the_lips_alone_bit_for_bit(femur):
    """``chisel_share = 0`` (and a file without the key) gives the lips' model of before: the same
    bits whatever the web, the thrust equal to sum_i F_i (E_L(z - z_i) - E_L(z - z_i+1)) written
    out, and the torque does not depend on the chisel share."""
    lips = _with_drill(femur, chisel_share=0.0)
    other_web = _with_drill(femur, chisel_share=0.0, web_thickness=0.9e-3)
    data = femur.to_dict()
    del data["drill"]["chisel_share"], data["drill"]["web_thickness"]
    old_file = bone_from_dict(data, source="old file")
    assert old_file.chisel_share == 0.0 and old_file.drill.web_thickness == pytest.approx(0.1 * 3.2e-3)
    z = np.linspace(-0.5e-3, femur.breakthrough_depth + 0.5e-3, 301)
    a, b, c = (drilling_forces(x, z, 1e-3, RPM_1500) for x in (lips, other_web, old_file))
    for x, y in ((a, b), (a, c)):
        for name in ("thrust", "torque", "thrust_depth_slope", "thrust_feed_slope"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name))
    edges, big = femur.boundaries, femur.point_length
    expected = [
        sum(
            _thrust_of_layer(femur, i, 1e-3, RPM_1500)
            * (_smoothstep(x - edges[i], big) - _smoothstep(x - edges[i + 1], big))
            for i in range(len(femur.layers))
        )
        for x in z
    ]
    np.testing.assert_allclose(a.thrust, expected, rtol=1e-13, atol=1e-12)
    np.testing.assert_array_equal(a.torque, drilling_forces(femur, z, 1e-3, RPM_1500).torque)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("chisel_share", 1.0, r"field 'drill\.chisel_share' = 1\.0: expected a number in \[0, 1\)"),
        ("chisel_share", -0.1, r"field 'drill\.chisel_share' = -0\.1: expected"),
        ("chisel_share", math.nan, r"field 'drill\.chisel_share' = nan: expected"),
        ("web_thickness", 3.2e-3, r"field 'drill\.web_thickness' = 0\.0032: expected a number in \(0, 0\.0032\) \(m\)"),
        ("web_thickness", 0.0, r"field 'drill\.web_thickness' = 0\.0: expected"),
    ],
)
def test_a_bad_chisel_is_refused_naming_the_field(femur, key, value, message):
    with pytest.raises(ConfigError, match=message) as caught:
        _with_drill(femur, **{key: value})
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("value", [0.0, -1.0e8, math.inf, "strong"])
def test_a_bad_cap_strength_is_one_line_naming_the_field(femur, value):
    data = femur.to_dict()
    data["model"]["cap_strength"] = value
    with pytest.raises(ConfigError, match=r"^cap\.toml: field 'model\.cap_strength' = .*: expected") as caught:
        bone_from_dict(data, source="cap.toml")
    assert "\n" not in str(caught.value)


def test_the_cap_example_is_the_femur_with_a_cap(femur):
    from vgtarm.drilling.bone import cap_thickness

    capped = load_bone(Path(__file__).resolve().parents[1] / "examples" / "bones" / "femur_diaphysis_cap.toml")
    assert capped.layers == femur.layers and capped.cap_strength == 1.5e8 and femur.cap_strength is None
    assert cap_thickness(capped, 20.0) == pytest.approx(math.sqrt(0.5 * 20.0 / 1.5e8))  # 0.26 mm
    assert cap_thickness(femur, 20.0) == 0.0


def test_the_bone_files_shipped_with_the_package_are_the_examples_byte_for_byte():
    """``vgtarm.drilling.FEMUR`` and ``FEMUR_CAP`` are copies kept in the package (a wheel has no
    ``examples/``): they stay the example files, so a run of either names the same bone."""
    from vgtarm.drilling import FEMUR, FEMUR_CAP

    for shipped in (FEMUR, FEMUR_CAP):
        assert shipped.read_bytes() == (BONES / shipped.name).read_bytes(), shipped.name

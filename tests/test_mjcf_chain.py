"""``pmpjax.MjcfChain``'s kinematics against C MuJoCo (``mj_kinematics``, ``mj_jacSite``).

The model exercises every constant the unrolled kinematics read: body offsets and orientations
(Euler angles, quaternions), several joints in one body, joint anchors away from the body origin,
non-zero reference positions (``ref`` → ``qpos0``), non-unit axes (MuJoCo normalises them), a slide,
and a branch whose joints do not move the site (zero Jacobian columns). The derivative of the
Jacobian (what the stiff solver and the fits differentiate) is checked against central differences
of C MuJoCo's ``mj_jacSite``.
"""

from pathlib import Path

import jax
import mujoco
import numpy as np
import pytest

import pmpjax as pj

ARM5 = str(Path(pj.__file__).parent / "data" / "examples" / "arm5.xml")

XML = """
<mujoco>
  <compiler angle="degree"/>
  <worldbody>
    <body name="base" pos="0.1 -0.05 0.3" euler="10 -20 30">
      <joint name="a" type="hinge" axis="0 0 1" pos="0.02 0 0" ref="15"/>
      <joint name="b" type="hinge" axis="1 1 0"/>
      <geom size="0.05"/>
      <body name="upper" pos="0 0 -0.3" quat="0.9 0.1 -0.3 0.2">
        <joint name="c" type="slide" axis="0 0.3 1" ref="0.05"/>
        <joint name="d" type="hinge" axis="0 -1 0" pos="0 0.01 0.02"/>
        <geom size="0.05"/>
        <body name="fore" pos="0.05 0 -0.25">
          <joint name="e" type="hinge" axis="0.2 0.9 -0.1" ref="-30"/>
          <geom size="0.04"/>
          <site name="tip" pos="0.02 -0.01 -0.2"/>
        </body>
      </body>
      <body name="other" pos="0 0.2 0">
        <joint name="f" type="hinge" axis="1 0 0"/>
        <geom size="0.03"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def c_mujoco(m, q):
    d = mujoco.MjData(m)
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    jac = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jac, None, 0)
    return d.site_xpos[0].copy(), jac


@pytest.mark.parametrize("xml", [XML, "arm5"])
def test_fk_and_jacobian_match_c_mujoco(xml):
    path = ARM5 if xml == "arm5" else xml
    m = mujoco.MjModel.from_xml_path(path) if xml == "arm5" else mujoco.MjModel.from_xml_string(xml)
    site = "hand" if xml == "arm5" else "tip"
    chain = pj.MjcfChain(path, site)
    Q = np.random.default_rng(1).uniform(-1.5, 1.5, (20, m.nq))
    ref = [c_mujoco(m, q) for q in Q]
    x, J = np.asarray(chain.fk(Q)), np.asarray(chain.jacobian(Q))
    np.testing.assert_allclose(x, [r[0] for r in ref], atol=1e-14)
    np.testing.assert_allclose(J, [r[1] for r in ref], atol=1e-14)
    if xml != "arm5":
        assert np.all(J[:, :, m.nq - 1] == 0.0)  # the branch's joint does not move the site
    # inside a caller's jit, on a (2, 10) batch
    xj = jax.jit(chain.fk)(Q.reshape(2, 10, m.nq))
    np.testing.assert_allclose(np.asarray(xj).reshape(20, 3), x, atol=1e-15)


def test_jacobian_derivative_matches_c_mujoco_differences():
    m = mujoco.MjModel.from_xml_string(XML)
    chain = pj.MjcfChain(XML, "tip")
    q = np.random.default_rng(2).uniform(-1.0, 1.0, m.nq)
    dq = np.random.default_rng(3).normal(size=m.nq)
    h = 1e-6
    fd = (c_mujoco(m, q + h * dq)[1] - c_mujoco(m, q - h * dq)[1]) / (2 * h)
    _, jvp = jax.jvp(lambda v: chain.jacobian(v), (q,), (dq,))
    np.testing.assert_allclose(np.asarray(jvp), fd, atol=1e-8)


# The joints the model above leaves out: hinges about +x, -x, +y and -z (plane rotations of either
# sign; "0 -2 0" is normalised to -y), tilted by body quaternions, with anchors off the body origin,
# and a slide along a coordinate axis; the site has its own orientation.
AXES_XML = """
<mujoco>
  <worldbody>
    <body pos="0.02 0.01 0.1" quat="0.8 0.2 -0.1 0.3">
      <joint type="hinge" axis="1 0 0" pos="0 0.01 0"/>
      <joint type="hinge" axis="0 -2 0"/>
      <geom size="0.03"/>
      <body pos="0.1 0 -0.2" quat="0.7 -0.3 0.4 0.1">
        <joint type="slide" axis="0 0 -1"/>
        <joint type="hinge" axis="0 0 -1" pos="0.01 0 0.02"/>
        <joint type="hinge" axis="-1 0 0"/>
        <geom size="0.03"/>
        <body pos="0 0.05 -0.2">
          <joint type="hinge" axis="0 1 0" pos="0 0.02 0"/>
          <geom size="0.03"/>
          <site name="tip" pos="0.03 -0.02 -0.1" quat="0.5 0.5 0.5 0.5"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_every_joint_kind_matches_c_mujoco():
    m = mujoco.MjModel.from_xml_string(AXES_XML)
    chain = pj.MjcfChain(AXES_XML, "tip")
    Q = np.random.default_rng(4).uniform(-2.0, 2.0, (8, m.nq))
    x, J = jax.jit(lambda c, q: c.fk_jac_soa(q))(chain, Q.T)
    for k, q in enumerate(Q):
        xr, Jr = c_mujoco(m, q)
        np.testing.assert_allclose(np.asarray(x)[:, k], xr, atol=1e-14)
        np.testing.assert_allclose(np.asarray(J)[:, :, k], Jr, atol=1e-14)
    q, dq, h = Q[0], np.random.default_rng(5).normal(size=m.nq), 1e-6
    fd = (c_mujoco(m, q + h * dq)[1] - c_mujoco(m, q - h * dq)[1]) / (2 * h)
    jvp = jax.jit(lambda c, q, dq: jax.jvp(lambda v: c.fk_jac_soa(v)[1], (q,), (dq,))[1])(chain, q, dq)
    np.testing.assert_allclose(np.asarray(jvp), fd, atol=1e-8)


def test_chain_is_a_pytree_of_the_mjx_models_arrays():
    a, b = pj.MjcfChain(ARM5, "hand"), pj.MjcfChain(ARM5, "hand")
    leaves = jax.tree_util.tree_leaves(a)
    assert [np.shape(v) for v in leaves] == [np.shape(v) for v in jax.tree_util.tree_leaves(a.mjx_model)]
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    assert type(jax.tree_util.tree_map(lambda v: v, a).mjx_model) is type(a.mjx_model)
    fk = jax.jit(lambda c, q: c.fk(q))
    q = np.full(5, 0.3)
    np.testing.assert_allclose(np.asarray(fk(b, q)), np.asarray(fk(a, q)), atol=0)
    assert fk._cache_size() == 1  # equal chains share one compile


@pytest.mark.parametrize("spoil, expect", [
    (lambda x: x.replace("</mujoco>", ""), r"not a loadable MJCF model: XML parse error \d+: .* Line number=\d+$"),
    (lambda x: x.replace('<joint name="wrist_flexion" axis="1 0 0" range="-70 80"/>',
                         '<joint name="wrist_flexion" type="ball"/>'),
     r"takes hinge and slide joints only; the model has the joint\(s\) 'wrist_flexion' \(ball\)$"),
    (lambda x: x.replace('<site name="hand"', '<site name="finger"'),
     r"`site` 'hand' is not a site of the model; its sites: \['finger'\]$"),
    ("folder", r"is a folder, not an MJCF file$"),
    ("missing", r"no such file$"),
    ("mot", r"not a loadable MJCF model: MuJoCo reads MJCF from \.xml files$"),
], ids=["malformed", "ball-joint", "no-such-site", "folder", "missing", "not-xml"])
def test_a_model_that_cannot_be_a_chain_is_refused_in_one_line_naming_its_file(tmp_path, spoil, expect):
    """The file first, then the reason (MuJoCo's multi-line messages joined into one line)."""
    import re

    path = tmp_path / "arm.xml"
    if spoil == "folder":
        path.mkdir()
    elif spoil == "mot":
        path = tmp_path / "S1_trial1.mot"
        path.write_text(Path(ARM5).read_text())
    elif spoil != "missing":
        path.write_text(spoil(Path(ARM5).read_text()))
    with pytest.raises(ValueError) as e:
        pj.MjcfChain(path, "hand")
    msg = str(e.value)
    assert msg.startswith(f"{path}: ") and "\n" not in msg and re.search(expect, msg), msg

"""The internal surface: kernels and helpers that ``fitting`` (and other packages built on pmpjax)
use beside the public API of ``pmpjax``. Like ``equinox.internal``: documented and tested, but not
part of the stable API — names here may change between releases without deprecation.

``fitting``'s library imports from ``pmpjax`` and from here only, never from a private module;
its application (``fitting._app``) imports pmpjax's application through that package's face,
``pmpjax._app``. Nothing here belongs to the application (command line, main job); a test
(tests/test_public_api.py) keeps both rules.
"""

# jax.jit for compile-bound kernels (fits, equilibria, MJX rollouts; pmpjax/_base/compile.py)
# Leading batch axes and padding (pmpjax/_base/batching.py)
from ._base.batching import bucket as bucket
from ._base.batching import flatten_batch as flatten_batch
from ._base.batching import on_host as on_host
from ._base.batching import pad_rows as pad_rows
from ._base.batching import row_chunks as row_chunks
from ._base.batching import unflatten_batch as unflatten_batch
from ._base.compile import FAST_COMPILE as FAST_COMPILE
from ._base.compile import TopLevelOptionsJit as TopLevelOptionsJit
from ._base.compile import fast_compile_jit as fast_compile_jit

# Keywords renamed before 1.0 (the old name warns for one release)
from ._base.deprecation import renamed_keywords as renamed_keywords

# Strict JSON files (NaN and inf as null; arrays as lists)
from ._base.jsontext import json_safe as json_safe
from ._base.jsontext import json_text as json_text
from ._base.jsontext import write_json as write_json

# Component-leading ("SoA") linear algebra: arrays (m, n, *batch) with components first
from ._base.linalg import det as det
from ._base.linalg import det_lists as det_lists
from ._base.linalg import mv as mv
from ._base.linalg import to_soa as to_soa

# The minimum-jerk profile shared by planners, set-point moves and synthetic data
from ._base.profiles import minimum_jerk as minimum_jerk

# Pytrees
from ._base.pytree import pytree_dataclass as pytree_dataclass
from ._base.pytree import replace as replace
from ._base.pytree import static_field as static_field

# sin and cos of one angle array in one pass (the chains' kinematics)
from ._base.trig import sincos as sincos

# Input validation: clear errors naming the argument, raised before tracing
from ._base.validate import as_array as as_array
from ._base.validate import as_prng_key as as_prng_key
from ._base.validate import check_finite_masked as check_finite_masked
from ._base.validate import check_joint_angles as check_joint_angles
from ._base.validate import check_positive as check_positive
from ._base.validate import check_positive_int as check_positive_int
from ._base.validate import check_prng_key as check_prng_key
from ._base.validate import check_seconds as check_seconds
from ._base.validate import check_spd as check_spd
from ._base.validate import csv_floats as csv_floats
from ._base.validate import input_file as input_file
from ._base.validate import is_concrete as is_concrete
from ._base.validate import open_npz as open_npz
from ._base.validate import output_dir as output_dir
from ._base.validate import read_text_file as read_text_file
from ._base.validate import to_jax as to_jax
from ._base.validate import warn_without_x64 as warn_without_x64
from ._base.validate import without_unit_checks as without_unit_checks

# MJCF site kinematics on MJX (position and Jacobian of a site, batched over postures)
from ._chains.mjcf import site_jacobians as site_jacobians

# Data
from ._data.hugmp import hugmp_directory as hugmp_directory

# λ0-PMP kernels: one equilibrium (no checks, vmappable), the RK4 integrator, the one weighted
# pseudo-inverse in its diagonal-weight SoA forms
from ._pmp.equilibria import equilibrium_one as equilibrium_one
from ._pmp.integrate import integrate as integrate
from ._pmp.redundancy import admittance_terms_soa as admittance_terms_soa
from ._pmp.redundancy import pinv_apply_diag_soa as pinv_apply_diag_soa
from ._pmp.redundancy import pinv_diag_lists as pinv_diag_lists

# simulate's RK4 step check, for callers that trace simulate inside their own kernels (skipped there)
from ._pmp.simulate import check_rk4_stability as check_rk4_stability
from ._pmp.simulate import forward_jacobians as forward_jacobians
from ._pmp.simulate import frozen_tangents as frozen_tangents

# Springy arm: argument checks, the per-item gravity equilibrium, and the batched MJX rollout
# behind ``rollout(..., backend="mjx")`` with its scripted controller and parked probe
from ._springy_arm.arm import PROBE_PARK as PROBE_PARK
from ._springy_arm.arm import Scripted as Scripted
from ._springy_arm.arm import _rollout_batch as rollout_batch  # noqa: F401
from ._springy_arm.arm import check_arm as check_arm
from ._springy_arm.primitives import arm_equilibrium_one as arm_equilibrium_one
from ._springy_arm.primitives import check_set_point as check_set_point
from ._springy_arm.primitives import check_stiffness as check_stiffness

# Wrist pointing: the normalised-time model movements and the trial bookkeeping behind
# ``fitting.analyze_pointing`` / ``predict_pointing`` / ``fit_time_constants``
from ._wrist.pointing import MODEL_DT as MODEL_DT
from ._wrist.pointing import MODEL_SPAN as MODEL_SPAN
from ._wrist.pointing import drop_trials as drop_trials
from ._wrist.pointing import model_grid as model_grid
from ._wrist.pointing import normalised_movements as normalised_movements
from ._wrist.pointing import trial_problems as trial_problems

# simulate's module, whose kernels benchmarks wrap within their own process (its compiled kernel
# captured to time it alone, its adaptive integrator wrapped to count steps); looked up by name,
# since the family's face binds ``simulate`` to the function
simulate_module = __import__("importlib").import_module(f"{__package__}._pmp.simulate")

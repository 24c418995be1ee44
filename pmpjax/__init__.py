"""pmpjax: differentiable JAX toolkit for human-like posture and movement of redundant chains."""

from ._analysis.movement import SmoothedPath as SmoothedPath
from ._analysis.movement import gcv_lambda as gcv_lambda
from ._analysis.movement import segment_by_speed as segment_by_speed
from ._analysis.movement import smooth_path as smooth_path
from ._analysis.reaches import Reaches as Reaches
from ._analysis.reaches import find_movements as find_movements
from ._base.compile import fast_compile_jit as fast_compile_jit
from ._base.status import Status as Status
from ._base.status import status_message as status_message
from ._chains.kinematics import Chain as Chain
from ._chains.kinematics import FunctionChain as FunctionChain
from ._chains.kinematics import PlanarArm as PlanarArm
from ._chains.kinematics import Wrist as Wrist
from ._chains.kinematics import manipulability as manipulability
from ._chains.mjcf import MjcfChain as MjcfChain
from ._chains.shoulder_elbow import ShoulderElbowArm as ShoulderElbowArm
from ._data.hugmp import HugmpSubject as HugmpSubject
from ._data.hugmp import hugmp_arrays as hugmp_arrays
from ._data.hugmp import load_hugmp as load_hugmp
from ._data.hugmp import motion_kinematics as motion_kinematics
from ._data.joint_angles import JointRecording as JointRecording
from ._data.joint_angles import read_joint_angles as read_joint_angles
from ._data.joint_angles import write_joint_angles as write_joint_angles
from ._data.matlab import ik_dataset_arrays as ik_dataset_arrays
from ._data.matlab import load_ik_dataset as load_ik_dataset
from ._data.matlab import read_mat as read_mat
from ._data.matlab import write_ik_dataset as write_ik_dataset
from ._data.matlab import write_mat as write_mat
from ._data.simulation_config import read_simulation_config as read_simulation_config
from ._pmp.equilibria import Equilibrium as Equilibrium
from ._pmp.equilibria import equilibrium_posture as equilibrium_posture
from ._pmp.integrate import SOLVERS as SOLVERS
from ._pmp.models import PMP1 as PMP1
from ._pmp.models import PMP2 as PMP2
from ._pmp.models import Lambda0PMP as Lambda0PMP
from ._pmp.models import damping_from_stiffness as damping_from_stiffness
from ._pmp.models import normalize_trace as normalize_trace
from ._pmp.planners import ArimotoPlanner as ArimotoPlanner
from ._pmp.planners import ConstantPlanner as ConstantPlanner
from ._pmp.planners import MinimumJerkPlanner as MinimumJerkPlanner
from ._pmp.planners import Planner as Planner
from ._pmp.planners import eq10_gain as eq10_gain
from ._pmp.redundancy import lambda0 as lambda0
from ._pmp.redundancy import nullspace_projector as nullspace_projector
from ._pmp.redundancy import task_damping as task_damping
from ._pmp.redundancy import weighted_pinv as weighted_pinv
from ._pmp.simulate import SaveAt as SaveAt
from ._pmp.simulate import Trajectory as Trajectory
from ._pmp.simulate import simulate as simulate
from ._pmp.simulate import simulate_sequence as simulate_sequence
from ._springy_arm.arm import ArmTrajectory as ArmTrajectory
from ._springy_arm.arm import CogArm as CogArm
from ._springy_arm.arm import arm_xml_path as arm_xml_path
from ._springy_arm.arm import load_arm as load_arm
from ._springy_arm.arm import rollout as rollout
from ._springy_arm.arm import run_controller as run_controller
from ._springy_arm.plots import plot_force_field as plot_force_field
from ._springy_arm.plots import plot_reflex as plot_reflex
from ._springy_arm.plots import plot_summed_moves as plot_summed_moves
from ._springy_arm.primitives import ArmEquilibrium as ArmEquilibrium
from ._springy_arm.primitives import Moves as Moves
from ._springy_arm.primitives import arm_equilibrium as arm_equilibrium
from ._springy_arm.primitives import blend as blend
from ._springy_arm.primitives import default_primitives as default_primitives
from ._springy_arm.primitives import equilibrium as equilibrium
from ._springy_arm.primitives import force_field as force_field
from ._springy_arm.primitives import move_velocity as move_velocity
from ._springy_arm.primitives import moves_from_targets as moves_from_targets
from ._springy_arm.primitives import summed_moves as summed_moves
from ._springy_arm.primitives import winner_take_all as winner_take_all
from ._springy_arm.reflexes import ReflexInputs as ReflexInputs
from ._springy_arm.reflexes import ReflexNetwork as ReflexNetwork
from ._springy_arm.reflexes import reflex_network as reflex_network
from ._springy_arm.reflexes import run_reflexes as run_reflexes
from ._springy_arm.reflexes import script_inputs as script_inputs
from ._springy_arm.reflexes import stack_inputs as stack_inputs
from ._wrist.center_out import DIRECTIONS as DIRECTIONS
from ._wrist.center_out import TARGET_RADIUS as TARGET_RADIUS
from ._wrist.center_out import center_out_targets as center_out_targets
from ._wrist.center_out import center_out_trials as center_out_trials
from ._wrist.center_out import target_radius as target_radius
from ._wrist.curvature import curvature_areas as curvature_areas
from ._wrist.curvature import curvature_measures as curvature_measures
from ._wrist.donders import DondersSurface as DondersSurface
from ._wrist.donders import evaluate_surface as evaluate_surface
from ._wrist.donders import fit_donders_surface as fit_donders_surface
from ._wrist.donders import model_donders_surface as model_donders_surface
from ._wrist.donders import plot_donders as plot_donders
from ._wrist.donders import screen_grid as screen_grid
from ._wrist.donders import surface_grid as surface_grid
from ._wrist.donders_recordings import DondersRecording as DondersRecording
from ._wrist.donders_recordings import read_recordings as read_recordings
from ._wrist.donders_recordings import recording_from_arrays as recording_from_arrays
from ._wrist.donders_recordings import synthetic_recordings as synthetic_recordings
from ._wrist.donders_recordings import write_recordings as write_recordings
from ._wrist.figure3 import FIGURE3 as FIGURE3
from ._wrist.figure3 import figure3_data as figure3_data
from ._wrist.figure3 import plot_figure3 as plot_figure3
from ._wrist.orientation import joint_angles_from_matrix as joint_angles_from_matrix
from ._wrist.orientation import joint_angles_from_quat as joint_angles_from_quat
from ._wrist.orientation import matrix_from_quat as matrix_from_quat
from ._wrist.orientation import matrix_from_rotvec as matrix_from_rotvec
from ._wrist.orientation import quat_from_joint_angles as quat_from_joint_angles
from ._wrist.orientation import quat_from_matrix as quat_from_matrix
from ._wrist.orientation import quat_from_rotvec as quat_from_rotvec
from ._wrist.orientation import rotvec_from_joint_angles as rotvec_from_joint_angles
from ._wrist.orientation import rotvec_from_matrix as rotvec_from_matrix
from ._wrist.orientation import rotvec_from_quat as rotvec_from_quat
from ._wrist.orientation import torsion_between as torsion_between
from ._wrist.orientation import wrist_rotation as wrist_rotation
from ._wrist.pointing import MOVEMENT_LABELS as MOVEMENT_LABELS
from ._wrist.pointing import PointingRecording as PointingRecording
from ._wrist.pointing import SyntheticPointing as SyntheticPointing
from ._wrist.pointing import read_pointing as read_pointing
from ._wrist.pointing import synthetic_pointing_experiment as synthetic_pointing_experiment
from ._wrist.pointing import write_pointing as write_pointing
from ._wrist.subjects import Subject as Subject
from ._wrist.subjects import load_subject as load_subject
from ._wrist.subjects import paper_subjects as paper_subjects
from ._wrist.subjects import subject_names as subject_names


def _installed_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pmpjax")
    except PackageNotFoundError:  # (a source tree that is not installed)
        return "0+unknown"


__version__ = _installed_version()

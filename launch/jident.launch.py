"""Start the jident_ros node set: simulator -> windowing -> diagnostic (docs/interfaces.md).

    ros2 launch jident_ros jident.launch.py
    ros2 launch jident_ros jident.launch.py namespace:=press3 real_time_factor:=0.0 record_root:=out/bags

Parameters: config/system.yaml and config/method.yaml (the model and the method, shared with the CLI),
then each node's section of config/nodes.yaml merged here with the launch arguments (merging in Python
avoids the params-file precedence quirk described in docs/interfaces.md).  The launch ends when the
simulator has run its cases (exit_when_done), unless simulator:=false (then windowing and diagnostic
wait for a real drive or `ros2 run jident_ros replay <bag>`).
"""
import os

import yaml
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, OpaqueFunction, RegisterEventHandler, TimerAction
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch_ros.actions import Node

ARGUMENTS = {
    "namespace": ("", "namespace of the drive, e.g. press3 (topics become /press3/drive/...)"),
    "config_dir": ("", "folder with system.yaml, method.yaml, nodes.yaml (default: the package's share/config)"),
    "simulator": ("true", "start the simulator (false: wait for a real drive or a replay)"),
    "use_sim_time": ("true", "windowing and diagnostic follow the simulator's drive clock (/clock; /<namespace>/clock "
                     "when namespaced: with two drives a shared /clock would mix their clocks)"),
    "real_time_factor": ("1.0", "simulator speed: drive seconds per wall second; 0 = as fast as the windowing node reads"),
    "cases": ("", "simulator: product | zip | grid (default: nodes.yaml)"),
    "backlash_width_m": ("", "windowing: K2 in m (default: nodes.yaml; the simulator's width is followed)"),
    "pattern_library": ("", "diagnostic: pattern library .npz (default: the CLI's cache path, built if missing)"),
    "record": ("", "diagnostic: record a rosbag2 MCAP bag, true | false (default: nodes.yaml, true)"),
    "record_root": ("", "diagnostic: bags go to <record_root>/rosbag2_<time> (default: nodes.yaml, the data dir)"),
    "record_dir": ("", "diagnostic, deprecated: record into exactly this bag directory instead of under record_root"),
    "p": ("", "diagnostic: KHM exponent p (default: nodes.yaml)"),
}


def _truthy(text):
    return str(text).strip().lower() in ("1", "true", "yes", "on")


def _setup(context):
    arg = {k: context.launch_configurations.get(k, d) for k, (d, _) in ARGUMENTS.items()}
    config = arg["config_dir"] or os.path.join(get_package_share_directory("jident_ros"), "config")
    files = [os.path.join(config, "system.yaml"), os.path.join(config, "method.yaml")]
    with open(os.path.join(config, "nodes.yaml"), encoding="utf-8") as f:
        sections = yaml.safe_load(f)

    def params(node_name, **overrides):
        p = dict(sections[f"/**/{node_name}"]["ros__parameters"])
        p.update({k: v for k, v in overrides.items() if v is not None})
        return files + [p]

    ns = arg["namespace"].strip("/")
    sim_time = _truthy(arg["use_sim_time"]) and _truthy(arg["simulator"])
    # /clock is global: two drives with sim time would follow each other's clock.  A namespaced drive gets
    # its own: the simulator publishes /<ns>/clock and its windowing and diagnostic nodes follow that one.
    remap = [("/clock", f"/{ns}/clock")] if ns and sim_time else []
    dsec = sections["/**/jident_diagnostic"]["ros__parameters"]
    record = _truthy(arg["record"]) if arg["record"] else bool(dsec["record"])
    recording_signals = record and bool(dsec["record_signals"])
    diag = Node(package="jident_ros", executable="diagnostic", name="jident_diagnostic", namespace=ns,
                output="screen", remappings=remap,
                parameters=params("jident_diagnostic", use_sim_time=sim_time,
                                  pattern_library=arg["pattern_library"] or None,
                                  record=record, record_root=arg["record_root"] or None,
                                  record_dir=arg["record_dir"] or None,
                                  p=float(arg["p"]) if arg["p"] else None))
    win = Node(package="jident_ros", executable="windowing", name="jident_windowing", namespace=ns, output="screen",
               remappings=remap,
               parameters=params("jident_windowing", use_sim_time=sim_time,
                                 backlash_width_from_topic=True if _truthy(arg["simulator"]) else None,
                                 backlash_width_m=float(arg["backlash_width_m"]) if arg["backlash_width_m"] else None))
    actions = [diag, win]
    if _truthy(arg["simulator"]):
        sim = Node(package="jident_ros", executable="simulator", name="jident_simulator", namespace=ns,
                   output="screen", remappings=remap,
                   parameters=params("jident_simulator", use_sim_time=False,
                                     real_time_factor=float(arg["real_time_factor"]),
                                     cases=arg["cases"] or None,
                                     # the windowing node (wait_for_node), plus the diagnostic node's
                                     # recorder when it records drive/signals
                                     wait_for_subscribers=2 if recording_signals else 1, wait_timeout_s=120.0))
        # give the diagnostic node a few seconds for the last window, then stop everything
        actions += [sim, RegisterEventHandler(OnProcessExit(target_action=sim, on_exit=[TimerAction(
            period=3.0, actions=[EmitEvent(event=Shutdown(reason="the simulator has run its cases"))])]))]
    return actions


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(k, default_value=d, description=text) for k, (d, text) in ARGUMENTS.items()]
        + [OpaqueFunction(function=_setup)])

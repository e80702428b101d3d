"""The parameters of the four nodes besides the model and method sections (config/system.yaml,
config/method.yaml): one schema for the nodes, the CLI and the tests.  config/nodes.yaml holds the same
defaults in the ROS 2 params-file format (a test keeps the two equal)."""


#: Parameters of the simulator node (besides the model sections of config/system.yaml), with their defaults.
SIMULATOR = {
    "cases": "product",                     # product | zip | grid
    "inertias_kgm2": [1.16, 1.073, 1.218],  # J1 of the cases
    "backlash_widths_m": [0.005],           # K2
    "consistencies_pa_sn": [0.025],         # eta_k
    "gap_samples": 400,                     # steady-state samples before each case
    "batch_size": 50,                       # samples per drive/signals message
    "real_time_factor": 1.0,                # drive seconds per wall second; 0 = as fast as possible
    "fast_sleep_s": 0.001,                  # pause per batch when real_time_factor = 0
    "max_lead_s": 2.0,                      # real_time_factor 0: at most this many drive seconds ahead of
                                            # the windowing node's drive/progress; 0 = no back-pressure
    "progress_timeout_s": 2.0,              # no drive/progress for this long while waiting: back-pressure off
    "start_time_s": 1.0,                    # drive clock of the first sample
    "repeat": 1,                            # passes through the case list; 0 = forever
    "publish_clock": True,
    "wait_for_subscribers": 0,              # wait until drive/signals has this many subscribers
    "wait_timeout_s": 30.0,
    "exit_when_done": True,                 # exit after the last case (else stay up, idle)
    "signals_queue_depth": 1000,
}


#: Parameters of the windowing node (besides the model sections of config/system.yaml), with their defaults.
WINDOWING = {
    "backlash_width_m": 0.005,            # K2 of inequality (1)
    "backlash_width_from_topic": False,   # follow drive/backlash_width (simulator, replay) when published
    "channels": ["alpha1", "alpha2", "omega2", "a1", "m_el", "omega1", "a2", "v2"],  # captured besides t
    "gap_tolerance": 1.5,                 # a step of t above this many sample periods is a gap
    "signals_queue_depth": 1000,
    "window_queue_depth": 50,
    "hardware_id": "",                    # default: the resolved drive namespace, e.g. /drive
    "diagnostics_period_s": 1.0,          # summary status period; 0 = only on events
    "progress_every_batches": 10,         # publish drive/progress (drive time read) every this many batches; 0 = off
    "input": "signals",                   # signals (drive/signals Float64MultiArray) | joint_states (sensor_msgs/JointState)
    "detector": "auto",                   # auto (flank for joint_states, paper for signals) | flank | paper
    "gear_ratio": 1.0,                    # N in delta = alpha1 - N alpha2 (flank detector)
    "motor_joint": "motor",               # joint_states: the motor joint (alpha1, omega1, m_el)
    "load_joint": "load",                 # joint_states: the load joint (alpha2, omega2)
    "use_imu": False,                     # joint_states: a1 from sensor_msgs/Imu on imu
    "imu_axis": "x",                      # linear_acceleration axis that is a1
    "batch_size": 50,                     # joint_states: samples per batch handed to the detector
}


#: Trend of J1 and the backlash width (issue 14; jident_ros.identify.trend.TrendConfig.from_parameters), parameters
#: of the diagnostic node.  0 means "not set" where TrendConfig takes None (ROS parameters cannot be None).
TREND = {
    "trend_enabled": True,                           # follow the trend and publish the "jident: trend" status
    "trend_state_file": "",                          # tracker state (JSON, written atomically); "" = not kept
    "trend_commissioning_windows": 20,               # windows that learn the baseline
    "trend_commissioning_duration_s": 0.0,           # instead: learn over this drive time, s (0 = by windows)
    "trend_inertia_baseline_kgm2": 0.0,              # given J1 baseline (0 = learn it)
    "trend_inertia_baseline_se_kgm2": 0.0,
    "trend_width_baseline_m": 0.0,                   # given width baseline (0 = learn it)
    "trend_width_baseline_se_m": 0.0,
    "trend_target_arl_windows": 1000000.0,           # in-control average run length the CUSUM is designed for
    "trend_cusum_reference_sd": 2.0,                 # CUSUM k, standard deviations
    "trend_cusum_threshold_sd": 0.0,                 # CUSUM h (0 = from trend_target_arl_windows)
    "trend_innovation_clip_sd": 4.0,                 # innovations clipped at +- this
    "trend_se_scale_from_commissioning": False,      # scale the reported errors by the commissioning scatter
    "trend_se_scale_max": 3.0,
    "trend_inertia_process_sd_pct_per_window": 0.02,  # J1 random walk, % of the baseline per window
    "trend_relearn_windows": 5,                      # windows after a change forming the new baseline
    "trend_change_hold_windows": 24,                 # WARN for this many windows after a change
    "trend_drift_warn_pct": 2.0,                     # J1 drift giving WARN, %
    "trend_drift_alarm_pct": 5.0,                    # J1 drift giving ERROR, %
    "trend_width_limit_m": 0.012,                    # backlash width limit (ERROR), m
    "trend_width_warn_m": 0.0,                       # WARN width, m (0 = 90 % of the limit)
    "trend_time_to_limit_warn_s": 2592000.0,         # WARN when the limit is projected sooner, s (30 days; 0 = off)
    "trend_width_regression_windows": 50,            # windows of the wear-rate regression
    "trend_width_se_floor_m": 1.0e-6,                # floor of the width standard error, m
    "trend_width_change_detection": True,            # CUSUM on the width too
    "trend_wear_significance_sd": 1.96,              # wear rate significant above this many standard errors
    "trend_max_changes_kept": 100,                   # change events kept in the state
}


#: Parameters of the diagnostic node (besides config/system.yaml and config/method.yaml), with their defaults.
DIAGNOSTIC = {
    "pattern_library": "",        # .npz; "" = the CLI's default path (~/.cache/jident_ros/patterns-<hash>.npz)
    "build_if_missing": True,     # build (and save) the library when the file does not exist
    "p": 2.0,                     # KHM exponent, one of method.p_values
    "image_method": True,         # run the paper's image method on every window
    "gap_method": "auto",         # auto | acceleration | gap_only | anchored | angle | speed | off
    "hardware_id": "",            # default: the resolved drive namespace, e.g. /drive
    "stale_after_s": 5.0,         # STALE status after this long without a window; 0 = never
    "record": True,               # record to a rosbag2 MCAP bag (docs/recording.md)
    "record_root": "",            # bags go to <root>/rosbag2_YYYY_MM_DD-HH_MM_SS; "" = $JIDENT_DATA_DIR/bags,
                                  # else ~/.local/share/jident_ros/bags
    "record_dir": "",             # deprecated: this exact bag directory (new or empty) instead of record_root
    "record_signals": True,       # also record drive/signals (+ drive/backlash_width, true_inertia, case)
    "max_bag_size_bytes": 1073741824,        # split the bag's .mcap file at 1 GiB; 0 = no limit
    "max_bag_duration_s": 3600.0,            # ... and every hour; 0 = no limit
    "retention_max_total_bytes": 20000000000,  # delete the oldest complete bags over 20 GB; 0 = no limit
    "retention_max_age_s": 604800.0,         # ... and those older than 7 days; 0 = no limit
    "window_queue_depth": 50,
    "signals_queue_depth": 1000,
    # the publishing policy (jident_ros.identify.verdict.VerdictPolicy; docs/interfaces.md "/diagnostics")
    "plausible_min_ratio": 0.5,   # J1 below this x the nominal is refused, not published
    "plausible_max_ratio": 1.5,   # J1 above this x the nominal is refused, not published
    "image_min_margin": 1.401117,  # the image method's class alone / its disagreement as a WARN only at a fused
                                  # margin >= this; 0 = never. From `python -m jident_ros.evaluation.verdicts threshold`
    "library_width_tolerance": 0.05,  # image method valid only with a library width within 5 % of the window's K2
    "max_torque_factor": 100.0,   # |m_el| above 100 x the base torque M_b is absurd: window refused
    "max_speed_factor": 10.0,     # |omega1|, |omega2| above 10 x the synchronous speed is absurd: window refused
    **TREND,                      # the trend (issue 14): wired by the node once it publishes the trend
}


#: Parameters of the replay node, with their defaults.
REPLAY = {
    "bag": "",                 # bag directory or .mcap file (or the first command-line argument)
    "rate": 1.0,               # playback speed factor; 0 = as fast as possible
    "fast_sleep_s": 0.001,     # pause between messages when rate = 0
    "max_lead_s": 2.0,         # rate 0: at most this many drive seconds ahead of drive/progress; 0 = off
    "progress_timeout_s": 2.0,  # no drive/progress for this long while waiting: back-pressure off
    "publish_clock": True,
    "topics": ["drive/signals", "drive/backlash_width", "drive/true_inertia", "drive/case"],
    "wait_for_subscribers": 0,  # wait until drive/signals has this many subscribers
    "wait_timeout_s": 30.0,
}

"""Motor–load simulator core (plain numpy/scipy; never imports rclpy)."""
from jident_ros.sim.params import BaseValues, GridParams, LoadParams, MotorParams, SamplingParams, SystemConfig
from jident_ros.sim.simulate import (
                                   CHANNELS,
                                   PAPER_SIGNALS,
                                   UNITS,
                                   Case,
                                   CaseTruths,
                                   WindowSet,
                                   add_measurement_noise,
                                   check_stable,
                                   paper_grid_cases,
                                   quantise_encoders,
                                   simulate_grid,
                                   steady_state,
)

__all__ = ["BaseValues", "GridParams", "LoadParams", "MotorParams", "SamplingParams", "SystemConfig",
           "CHANNELS", "PAPER_SIGNALS", "UNITS", "Case", "CaseTruths", "WindowSet", "add_measurement_noise", "check_stable",
           "paper_grid_cases", "quantise_encoders", "simulate_grid", "steady_state"]

"""jident_ros: identification of the moment of inertia J1 of an induction-motor
drive from the backlash-zone transient (wavelet scalograms + k-harmonic means),
packaged as a ROS 2 ament_python package that also installs with plain pip."""

__version__ = "0.1.0"

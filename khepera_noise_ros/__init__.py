"""khepera_noise_ros: Meeden (1998) sensor-noise models for evolving Khepera controllers."""
__version__ = '0.1.0'

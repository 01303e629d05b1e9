"""Exact arithmetic: matrix exponentials with a certified error, exact zero-order-hold
propagation, floating-point rounding analysis, the norms the ROS layer reports."""

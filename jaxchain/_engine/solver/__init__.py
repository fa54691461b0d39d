"""The solvers offered by name (`registry`), ROS34PW2 with its diagonal W matrix
(`rosenbrock`), and jaxchain's PI step-size controller (`controller`)."""

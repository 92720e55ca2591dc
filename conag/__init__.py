"""ConAg process glue: the `conag` command line and how processes open the zenoh bus."""

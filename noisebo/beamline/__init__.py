"""noisebo in the bluesky control stack (the extra ``noisebo[bluesky]``): the campaign as a bluesky
plan (``plan``), and a simulated EPICS IOC with its ophyd-async devices (``sim_ioc``,
``sim_devices``) for the tests, the example and the benchmark."""

"""Free ports for Channel Access servers on loopback."""

import socket


def free_port() -> int:
    """A port free for both TCP and UDP on 127.0.0.1 (Channel Access serves on both)."""
    with socket.socket() as tcp, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        tcp.bind(("127.0.0.1", 0))
        port = tcp.getsockname()[1]
        udp.bind(("127.0.0.1", port))
        return port

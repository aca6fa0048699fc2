"""The daemon's socket under many clients: nobody refused, the web's client keeps few connections."""

import socket
import threading

import pytest
from daemon_helpers import service

from appliance.daemon import rpc


@pytest.fixture
def daemon(tmp_path):
    svc, _ = service(tmp_path)
    sock = tmp_path / "d.sock"
    server = rpc.serve(svc, sock)
    yield sock, server
    server.shutdown()
    server.server_close()
    svc.close()


def together(n, fn):
    """Run fn(i) in n threads released at the same instant; the exceptions they raised."""
    gate = threading.Barrier(n)
    errors = []

    def run(i):
        gate.wait()
        try:
            fn(i)
        except Exception as e:
            errors.append(e)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    return errors


def test_fifty_clients_connecting_at_once_are_all_served(daemon):
    sock, server = daemon
    assert server.request_queue_size >= 50
    # each its own client, so fifty connect() calls race for the accept queue
    clients = [rpc.BenchClient(sock, timeout=20) for _ in range(50)]
    for _ in range(3):
        errors = together(50, lambda i: clients[i].state())
        assert errors == [], errors[:3]
    for c in clients:
        c.close()


def test_a_shared_client_reuses_a_few_connections(daemon):
    sock, _ = daemon
    client = rpc.BenchClient(sock, timeout=20, max_connections=4)
    opened = []
    connect = client._connect

    def counting(timeout):
        opened.append(1)
        return connect(timeout)

    client._connect = counting
    errors = together(50, lambda i: [client.state() for _ in range(5)] and client.jobs())
    assert errors == [], errors[:3]
    assert 1 <= len(opened) <= 4  # 300 calls, at most four connections
    assert len(client._idle) == len(opened)
    client.close()
    assert client._idle == []


def test_a_dead_kept_connection_is_replaced(daemon):
    sock, _ = daemon
    client = rpc.BenchClient(sock, timeout=20)
    assert client.state()["state"] == "idle"
    conn = client._idle[0]
    conn.sock.shutdown(socket.SHUT_RDWR)  # as if the daemon had restarted since
    assert client.state()["state"] == "idle"  # a fresh connection, no error for the caller
    assert client._idle and client._idle[0] is not conn
    client.close()

"""The standalone emulator (`wideprint emulator`): the command channel on a pseudo-terminal
(or a TCP port, for pyserial's socket:// URLs) and the data channel on TCP, served by one
selector loop so the Printer is only ever touched from one thread."""

from __future__ import annotations

import os
import selectors
import socket
import time
import traceback
import tty

from .printer import Printer


class EmulatorServer:
    def __init__(self, printer: Printer, host: str = "127.0.0.1", data_port: int = 0,
                 serial_tcp_port: int | None = None, data_pty: bool = False):
        self.printer = printer
        self.sel = selectors.DefaultSelector()
        self.running = False
        # command channel: a pty, or TCP when serial_tcp_port is given
        self.pty_path = None
        self._serial_conn: socket.socket | None = None
        if serial_tcp_port is None:
            self.master, slave = os.openpty()
            tty.setraw(slave)
            self.pty_path = os.ttyname(slave)
            self._slave = slave          # kept open so the pty survives host reconnects
            os.set_blocking(self.master, False)
            self.sel.register(self.master, selectors.EVENT_READ, self._on_pty)
            self.serial_listener = None
        else:
            self.master = None
            self.serial_listener = self._listen(host, serial_tcp_port, self._accept_serial)
        self.data_listener = self._listen(host, data_port, self._accept_data)
        self._last_serial = 0.0
        self._data_conn: socket.socket | None = None
        # the PCI card's device node, stood in for by a pty: one fd, blocks in, reports out
        self.data_pty_path = None
        self._data_master = None
        if data_pty:
            self._data_master, dslave = os.openpty()
            tty.setraw(dslave)
            self.data_pty_path = os.ttyname(dslave)
            self._data_slave = dslave
            os.set_blocking(self._data_master, False)
            self.sel.register(self._data_master, selectors.EVENT_READ, self._on_data_pty)

    def _listen(self, host, port, handler) -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((host, port))
        s.listen(1)
        s.setblocking(False)
        self.sel.register(s, selectors.EVENT_READ, handler)
        return s

    @property
    def data_port(self) -> int:
        return self.data_listener.getsockname()[1]

    @property
    def serial_spec(self) -> str:
        if self.pty_path:
            return self.pty_path
        return "socket://%s:%d" % self.serial_listener.getsockname()

    @property
    def device_spec(self) -> str:
        host = self.data_listener.getsockname()[0]
        if self.data_pty_path:
            return f"serial={self.serial_spec},data={self.data_pty_path}"
        return f"serial={self.serial_spec},data=tcp://{host}:{self.data_port}"

    # -- handlers ---------------------------------------------------------------------------
    def _on_pty(self, fd) -> None:
        try:
            data = os.read(fd, 65536)
        except BlockingIOError:
            return
        except OSError:
            return
        out = self.printer.serial_in(data, self._gap())
        if out:
            os.write(fd, out)
        self._flush_data_out()

    def _gap(self) -> bool:
        """Inter-frame timeout: 20 character times at the line's baud rate, but never less
        than 50 ms, the scheduling slack of a host that is not real time."""
        now = time.monotonic()
        gap = now - self._last_serial > max(0.05, 200 / self.printer.baud)
        self._last_serial = now
        return gap

    def _accept_serial(self, sock) -> None:
        conn, _ = sock.accept()
        conn.setblocking(False)
        if self._serial_conn:
            self.sel.unregister(self._serial_conn)
            self._serial_conn.close()
        self._serial_conn = conn
        self.sel.register(conn, selectors.EVENT_READ, self._on_serial_sock)

    def _on_serial_sock(self, conn) -> None:
        try:
            data = conn.recv(65536)
        except BlockingIOError:
            return
        if not data:
            self.sel.unregister(conn)
            conn.close()
            self._serial_conn = None
            return
        out = self.printer.serial_in(data, self._gap())
        if out:
            conn.sendall(out)
        self._flush_data_out()

    def _accept_data(self, sock) -> None:
        conn, _ = sock.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if self._data_conn:
            self._drop_data()
        conn.setblocking(False)
        self._data_conn = conn
        self.printer.data_link_up()
        self.sel.register(conn, selectors.EVENT_READ, self._on_data)

    def _drop_data(self) -> None:
        conn = self._data_conn
        self._data_conn = None
        self.sel.unregister(conn)
        conn.close()
        self.printer.data_link_lost()

    def _on_data(self, conn) -> None:
        try:
            data = conn.recv(1 << 20)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self._drop_data()
            return
        self.printer.data_in(data)
        if not self.printer.link_alive:      # an injected link drop
            self._drop_data()
            return
        self._flush_data_out()

    def _on_data_pty(self, fd) -> None:
        try:
            data = os.read(fd, 1 << 20)
        except (BlockingIOError, OSError):
            return
        self.printer.data_link_up()
        self.printer.data_in(data)
        self._flush_data_out()

    def _flush_data_out(self) -> None:
        """FPGA reports go out on the data connection, whichever input caused them."""
        out = self.printer.data_out()
        if out and self._data_master is not None:
            os.write(self._data_master, out)
            return
        if out and self._data_conn is not None:
            self._data_conn.setblocking(True)
            try:
                self._data_conn.sendall(out)
            except OSError:
                self._drop_data()
                return
            self._data_conn.setblocking(False)

    def serve_forever(self, poll: float = 0.5) -> None:
        self.running = True
        while self.running:
            for key, _ in self.sel.select(poll):
                try:
                    key.data(key.fileobj)
                except Exception:  # noqa: BLE001 - a device keeps running; the log says why
                    traceback.print_exc()
                    self.printer.log("emulator_error", error=traceback.format_exc(limit=3))

    def stop(self) -> None:
        self.running = False

    def close(self) -> None:
        self.printer.close()
        for s in (self.data_listener, self.serial_listener, self._data_conn, self._serial_conn):
            if s is not None:
                s.close()
        if self.master is not None:
            os.close(self.master)
            os.close(self._slave)
        if self._data_master is not None:
            os.close(self._data_master)
            os.close(self._data_slave)

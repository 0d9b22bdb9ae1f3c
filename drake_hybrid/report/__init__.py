"""What the ``drake-hybrid`` commands say about their results, for the command line, a notebook or a test:
the verdicts, the ``--json`` payloads and the text. The command line parses its arguments, calls the
package and prints these; nothing here parses arguments, runs a simulation or writes a file.

* ``report.run``: a simulation's summary (``simulate``'s printout: each row's errors with the run's
  phases and notes, the impedance's check, the constraint's residual, a job's path) and a sweep's;
* ``report.eigenvalues``: ``analyze``'s judgement of a linearization (designed against linearized
  eigenvalues, matched, matched as predicted or not; its exit code, its lines and its ``--json``);
* ``report.hardware``: the ``hardware`` command's summary lines.
"""

"""The package's TemplateSystems (pydrake's scalar-convertible systems) at no import cost.

pydrake's ``TemplateSystem`` registers each instantiation's scalar-conversion methods with the
module it finds by ``inspect.stack()``, which walks every frame of the calling thread and, for
each frame of the import system, every loaded module. Where ``Name = Name_[None]`` runs, inside
the imports of a command, that cost tens of milliseconds per system (measured: 1 to 4 s of the
``drake-hybrid simulate`` start for the package's thirteen systems, with the machine's load).
``default_instantiation(template)`` makes the same ``template[None]`` on a short-lived thread,
whose stack is a few frames deep: about a millisecond each. The definitions are imported with
their modules as before; ``TemplateSystem.define`` is given its module (``scope``) for the same
reason.
"""

import threading


def default_instantiation(template):
    """``template[None]`` (its float instantiation), made on a thread of its own (module docstring).
    The instantiation defines a class and imports nothing, so the import that calls this waits for
    no lock the thread needs."""
    made, failed = [], []

    def instantiate():
        try:
            made.append(template[None])
        except BaseException as error:       # re-raised in the caller's thread
            failed.append(error)

    worker = threading.Thread(target=instantiate, name=f"instantiate {template.name}", daemon=True)
    worker.start()
    worker.join()
    if failed:
        raise failed[0]
    return made[0]

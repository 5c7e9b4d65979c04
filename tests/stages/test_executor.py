"""The executors' contract on closed-form tasks: results in task order, a raising task named with its error while
the others run, a task waiting for a failed one not run; the local executor here, Ray in test_ray_executor.py."""

from __future__ import annotations

import pytest

from pipeline.stages.executor import ExecutorSpec, Task, TaskFailures, executor_from_args, run_tasks


def square(x: int) -> int:
    return x * x


def refuse(x: int) -> int:
    raise ValueError(f"no {x}")


def closed_form_tasks() -> list[Task]:
    """Four tasks: 2*2, a failure, 3*3 waiting for the failure, 4*4 waiting for 2*2."""
    return [Task("two", square, (2,)), Task("bad", refuse, (7,)), Task("three", square, (3,), after=(1,)),
            Task("four", square, (4,), after=(0,))]


def check_contract(spec: ExecutorSpec) -> None:
    done: dict[int, int] = {}
    failed: dict[int, str] = {}
    with pytest.raises(TaskFailures) as raised:
        run_tasks(closed_form_tasks(), spec, on_done=done.__setitem__, on_failed=failed.__setitem__)
    assert done == {0: 4, 3: 16}
    assert raised.value.failures == {"bad": "ValueError: no 7", "three": "not run: bad failed"}
    assert failed == {1: "ValueError: no 7", 2: "not run: bad failed"}
    assert str(raised.value).startswith("2 of 4 tasks failed")
    assert run_tasks([Task(str(i), square, (i,)) for i in range(5)], spec) == [0, 1, 4, 9, 16]


def test_the_local_executor_keeps_the_contract():
    check_contract(ExecutorSpec("local"))


def test_executor_flags_are_checked():
    import argparse

    with pytest.raises(ValueError, match="--ray-address, --task-cpus and --ray-timeout apply to --executor ray only"):
        executor_from_args(argparse.Namespace(executor="local", ray_address="h:1", task_cpus=1))
    with pytest.raises(ValueError, match="--executor: expected one of local, ray, got 'dask'"):
        ExecutorSpec("dask")

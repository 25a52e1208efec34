"""One process harness for tests, testbed and benchmarks (see the package README)."""
from cnr_harness.master import RosMaster, master_answers, master_proxy
from cnr_harness.process import Proc, WaitTimeout, free_port, stop_process, wait_until

__all__ = ['Proc', 'RosMaster', 'WaitTimeout', 'free_port', 'master_answers', 'master_proxy', 'stop_process',
           'wait_until']

"""The lab's fault-injection harnesses (not installed with the package).

* `chaos`: `python3 -m faults.chaos SCENARIO` builds while agent (and world) processes are
  SIGKILLed at random;
* `partition`, `netns`: multi-host runs in network namespaces, with links cut and healed.
"""

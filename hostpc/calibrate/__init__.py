"""The shared calibration procedure, the same for every measurement method: the runner
(plan, acquire, fit, guarded push, verify, report), its journal and resume, the push
decision and its execution, the verification test, robot time, the result document and
summary, refusals. It drives a `hostpc.methods.base.Method` through a
`hostpc.robots.base.RobotAdapter`; the methods never import this package."""

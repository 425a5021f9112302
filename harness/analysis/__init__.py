"""Linear analysis of a scenario's closed loop, below the run API and the studies: the loop broken at the
plant input (``analyze``, its figures ``analyze_plots``), the laws as linear discrete systems
(``linear_law``), the limit cycles friction drives (``limit_cycle``) and the residual cycle of friction
and encoder counts that sets a run's amplitude bound before it runs (``residual_cycle``). Needs
python-control, imported only when an analysis is asked for."""

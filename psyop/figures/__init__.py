"""The figures `make figures` draws: each study's figures from statistics tables (`study_figures`), adaptive
tracks (`adaptive_figures`), the optics figures (`optics_figures`), frame timing (`timing_figures`), their shared
labels and style (`labels`) and the one way a figure is written (`output`)."""

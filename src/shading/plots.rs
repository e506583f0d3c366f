//! Plots (paper, Fig. 2).

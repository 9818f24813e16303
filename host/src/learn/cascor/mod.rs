//! Cascade-Correlation (Fahlman & Lebiere 1990) with Quickprop (Fahlman 1988).

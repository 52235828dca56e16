//! Xsens MTi Xbus driver (work in progress on its own branch).
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

//! Runnable examples of yarnify live beside this file: `serial/`.

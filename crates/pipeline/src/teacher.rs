//! `teacher`: zero-shot disparities of the frozen teacher for every real pair.

//! Least-recently-used lists, one per size class, over the pool's chunks: intrusive doubly
//! linked lists in arrays indexed by chunk, so touching a chunk (every visible tile, every
//! frame) is O(1). A chunk is appended when used, so each list runs from the least recently
//! used chunk at its head to the most recently used at its tail.

const NIL: usize = usize::MAX;

#[derive(Clone, Debug)]
pub struct LruLists {
    head: Vec<usize>,
    tail: Vec<usize>,
    prev: Vec<usize>,
    next: Vec<usize>,
    /// The class whose list holds the chunk, if any.
    list: Vec<Option<usize>>,
}

impl LruLists {
    pub fn new(classes: usize, chunks: usize) -> LruLists {
        LruLists {
            head: vec![NIL; classes],
            tail: vec![NIL; classes],
            prev: vec![NIL; chunks],
            next: vec![NIL; chunks],
            list: vec![None; chunks],
        }
    }

    /// Appends `chunk` (in no list) as the most recently used of `class`.
    pub fn push_back(&mut self, class: usize, chunk: usize) {
        debug_assert!(self.list[chunk].is_none(), "chunk {chunk} listed twice");
        let last = self.tail[class];
        self.prev[chunk] = last;
        self.next[chunk] = NIL;
        match last {
            NIL => self.head[class] = chunk,
            l => self.next[l] = chunk,
        }
        self.tail[class] = chunk;
        self.list[chunk] = Some(class);
    }

    /// Takes `chunk` out of its list (nothing if it is in none).
    pub fn remove(&mut self, chunk: usize) {
        let Some(class) = self.list[chunk].take() else {
            return;
        };
        let (p, n) = (self.prev[chunk], self.next[chunk]);
        match p {
            NIL => self.head[class] = n,
            p => self.next[p] = n,
        }
        match n {
            NIL => self.tail[class] = p,
            n => self.prev[n] = p,
        }
        self.prev[chunk] = NIL;
        self.next[chunk] = NIL;
    }

    /// Moves `chunk` (in `class`'s list or in none) to the tail: most recently used.
    pub fn touch(&mut self, class: usize, chunk: usize) {
        self.remove(chunk);
        self.push_back(class, chunk);
    }

    /// The class whose list holds `chunk`.
    pub fn list_of(&self, chunk: usize) -> Option<usize> {
        self.list[chunk]
    }

    /// `class`'s chunks, least recently used first.
    pub fn iter(&self, class: usize) -> impl Iterator<Item = usize> + '_ {
        let mut at = self.head[class];
        std::iter::from_fn(move || {
            let c = at;
            if c == NIL {
                return None;
            }
            at = self.next[c];
            Some(c)
        })
    }

    pub fn oldest(&self, class: usize) -> Option<usize> {
        Some(self.head[class]).filter(|&c| c != NIL)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a plain vector model, on a fixed pseudo-random sequence of operations.
    #[test]
    fn lists_follow_a_vector_model() {
        let (classes, chunks) = (3, 20);
        let mut lists = LruLists::new(classes, chunks);
        let mut model: Vec<Vec<usize>> = vec![Vec::new(); classes];
        let mut rng = splitmix::Rng(0x9e37_79b9_7f4a_7c15);
        for _ in 0..5000 {
            let chunk = rng.below(chunks);
            let class = chunk % classes;
            let listed = model[class].contains(&chunk);
            match rng.below(3) {
                0 if !listed => {
                    lists.push_back(class, chunk);
                    model[class].push(chunk);
                }
                1 => {
                    lists.remove(chunk);
                    model[class].retain(|&c| c != chunk);
                }
                _ => {
                    lists.touch(class, chunk);
                    model[class].retain(|&c| c != chunk);
                    model[class].push(chunk);
                }
            }
            for (k, m) in model.iter().enumerate() {
                assert_eq!(&lists.iter(k).collect::<Vec<_>>(), m);
                assert_eq!(lists.oldest(k), m.first().copied());
            }
            for c in 0..chunks {
                let expected = model.iter().position(|m| m.contains(&c));
                assert_eq!(lists.list_of(c), expected);
            }
        }
    }
}
